//! naofarm: the `Lᵀ D L` factorisation of a multibody's mass matrix that
//! keeps the tree's sparsity (Featherstone, *Rigid Body Dynamics
//! Algorithms*, §6.5).
//!
//! Number the degrees of freedom so that each one's parent, `λ(i)`, comes
//! before it (the previous one of its joint, or the last one of its
//! nearest ancestor's joint). A tree's joint-space inertia `H` has
//! `H[i][j] = 0` unless one of `i`, `j` is an ancestor of the other, and
//! `H = Lᵀ D L` with a unit lower-triangular `L` of the same pattern: no
//! fill-in. Each row of `L` is stored packed, its ancestors' entries from the
//! root down, so the factorisation costs `O(Σ depth²)` and a solve
//! `O(Σ depth)` against the dense LU's `O(n³)` and `O(n²)`. The pattern
//! (which entries each row holds) is built once per tree, not per matrix.
//! Must not: pivot (`H` is symmetric positive definite), or read an entry
//! of `H` outside the pattern.

use crate::alloc_prelude::*;
use crate::math::Real;
use crate::utils::slice_blas::lu_solve;
use na::{DMatrix, Dyn, LU};

/// No parent: a degree of freedom of the root's joint, or the first free
/// one of a tree.
pub const NO_PARENT: usize = usize::MAX;

/// `H = Lᵀ D L` of a tree's symmetric positive-definite joint-space inertia.
#[derive(Clone, Debug, Default)]
#[cfg_attr(feature = "serde-serialize", derive(serde::Serialize, serde::Deserialize))]
pub struct TreeLdl {
    /// The tree the pattern below was built for.
    parents: Vec<usize>,
    /// Each degree of freedom's first entry in `l` and `ancestors`.
    row_start: Vec<usize>,
    /// Row `i` of `L` below the diagonal, packed: its ancestors' entries from
    /// the root down (ascending: a parent comes before its child). An
    /// ancestor's row is a prefix of its descendant's.
    l: Vec<Real>,
    /// The degree of freedom of each entry of `l`.
    ancestors: Vec<usize>,
    /// Each degree of freedom's first entry in `runs`.
    run_start: Vec<usize>,
    /// Row `i`'s ancestors as runs of consecutive degrees of freedom
    /// `(first, len)`, in order: the solves' loops run over slices.
    runs: Vec<(usize, usize)>,
    /// The diagonal `D`.
    d: Vec<Real>,
}

impl TreeLdl {
    /// The factorisation of the leading `parents.len()` block of `h`,
    /// reading its lower triangle on the tree's pattern only. `parents[i]`
    /// is `λ(i) < i`, or [`NO_PARENT`]. Returns `None` if a pivot is not
    /// positive and finite (`h` is not positive definite).
    pub fn factor(h: &DMatrix<Real>, parents: &[usize]) -> Option<Self> {
        let mut this = Self::default();
        this.refactor(h, parents).then_some(this)
    }

    /// [`Self::factor`] into `self`'s buffers; `false` if refused (`self`
    /// then holds no usable factorisation).
    pub fn refactor(&mut self, h: &DMatrix<Real>, parents: &[usize]) -> bool {
        let n = parents.len();
        assert!(h.nrows() >= n && h.ncols() >= n, "TreeLdl: matrix too small");
        if self.parents != parents {
            self.build_pattern(parents);
        }
        self.l.clear();
        self.d.clear();
        for i in 0..n {
            self.d.push(h[(i, i)]);
            let (r0, r1) = (self.row_start[i], self.row_start[i + 1]);
            for e in r0..r1 {
                self.l.push(h[(i, self.ancestors[e])]);
            }
        }

        for k in (0..n).rev() {
            let dk = self.d[k];
            if !(dk > 0.0 && dk.is_finite()) {
                return false;
            }
            let k0 = self.row_start[k];
            // From the parent up: row k's entries before `p` are still H's.
            for p in (0..self.row_start[k + 1] - k0).rev() {
                let i = self.ancestors[k0 + p];
                let hki = self.l[k0 + p];
                let a = hki / dk;
                self.d[i] -= a * hki;
                // H[i][j] -= a H[k][j] for the ancestors j of i: row i is
                // row k's first p entries.
                let i0 = self.row_start[i];
                let (head, tail) = self.l.split_at_mut(k0);
                for (hij, hkj) in head[i0..i0 + p].iter_mut().zip(&tail[..p]) {
                    *hij -= a * *hkj;
                }
                self.l[k0 + p] = a;
            }
        }
        true
    }

    /// Each row's ancestors and their runs for the tree `parents`.
    fn build_pattern(&mut self, parents: &[usize]) {
        self.parents.clear();
        self.parents.extend_from_slice(parents);
        self.row_start.clear();
        self.ancestors.clear();
        self.run_start.clear();
        self.runs.clear();
        for (i, &p) in parents.iter().enumerate() {
            assert!(p == NO_PARENT || p < i, "TreeLdl: a parent after its child");
            self.row_start.push(self.ancestors.len());
            self.run_start.push(self.runs.len());
            // The parent's ancestors, then the parent.
            if p != NO_PARENT {
                let (p0, p1) = (self.row_start[p], self.row_start[p + 1]);
                self.ancestors.extend_from_within(p0..p1);
                self.ancestors.push(p);
                let (r0, r1) = (self.run_start[p], self.run_start[p + 1]);
                self.runs.extend_from_within(r0..r1);
                match self.runs[r1..].last_mut() {
                    Some(last) if last.0 + last.1 == p => last.1 += 1,
                    _ => self.runs.push((p, 1)),
                }
            }
        }
        self.row_start.push(self.ancestors.len());
        self.run_start.push(self.runs.len());
    }

    /// The dimension of the factored matrix.
    pub fn dim(&self) -> usize {
        self.d.len()
    }

    /// Solves `H x = b` in place.
    pub fn solve(&self, b: &mut [Real]) {
        let n = self.d.len();
        assert_eq!(n, b.len(), "TreeLdl: dimension mismatch");
        // Lᵀ y = b, from the leaves up.
        for i in (0..n).rev() {
            let bi = b[i];
            if bi != 0.0 {
                let mut e = self.row_start[i];
                for &(first, len) in &self.runs[self.run_start[i]..self.run_start[i + 1]] {
                    for (bj, lij) in b[first..first + len].iter_mut().zip(&self.l[e..e + len]) {
                        *bj -= *lij * bi;
                    }
                    e += len;
                }
            }
        }
        for (bi, di) in b.iter_mut().zip(&self.d) {
            *bi /= *di;
        }
        // L x = y, from the root down.
        for i in 0..n {
            let mut xi = b[i];
            let mut e = self.row_start[i];
            for &(first, len) in &self.runs[self.run_start[i]..self.run_start[i + 1]] {
                for (xj, lij) in b[first..first + len].iter().zip(&self.l[e..e + len]) {
                    xi -= *lij * *xj;
                }
                e += len;
            }
            b[i] = xi;
        }
    }
}

/// A multibody's inverse joint-space inertia: the tree's factorisation, or
/// the dense LU when the tree's is refused (a pivot not positive).
#[derive(Clone, Debug)]
#[cfg_attr(feature = "serde-serialize", derive(serde::Serialize, serde::Deserialize))]
pub enum MassInverse {
    /// `H = Lᵀ D L` on the tree's pattern.
    Tree(TreeLdl),
    /// Dense LU with partial pivoting.
    Dense(LU<Real, Dyn, Dyn>),
}

impl Default for MassInverse {
    fn default() -> Self {
        Self::Tree(TreeLdl::default())
    }
}

impl MassInverse {
    /// The factorisation of the leading `parents.len()` block of the
    /// symmetric `h` (see [`TreeLdl::factor`]).
    pub fn new(h: &DMatrix<Real>, parents: &[usize]) -> Self {
        let mut this = Self::default();
        this.update(h, parents);
        this
    }

    /// Refactors `h` in place, reusing the tree's buffers.
    pub fn update(&mut self, h: &DMatrix<Real>, parents: &[usize]) {
        if let Self::Tree(ldl) = self {
            if ldl.refactor(h, parents) {
                return;
            }
        } else {
            let mut ldl = TreeLdl::default();
            if ldl.refactor(h, parents) {
                *self = Self::Tree(ldl);
                return;
            }
        }
        let n = parents.len();
        *self = Self::Dense(LU::new(h.view((0, 0), (n, n)).into_owned()));
    }

    /// Solves `H x = b` in place.
    pub fn solve(&self, b: &mut [Real]) {
        match self {
            Self::Tree(ldl) => ldl.solve(b),
            Self::Dense(lu) => lu_solve(lu, b),
        }
    }
}
