//! CMA-ES, the (μ/μ_w, λ) evolution strategy with rank-one and rank-μ
//! covariance updates and cumulative step-size adaptation, as Hansen's
//! tutorial ("The CMA Evolution Strategy: A Tutorial", 2016) states it: the
//! baseline CLOP is measured against in `naofarm bench clop`.
//!
//! Written here as a small ask/tell state machine rather than taken from the
//! `cmaes` crate: that crate runs the objective itself (no ask/tell), so the
//! harness could not hand every algorithm the same outcome stream and stop at
//! an exact game budget, and it pulls an older nalgebra and plotting by
//! default. It is a benchmark baseline: no I/O, no clock, seeded.

use nalgebra::{DMatrix, DVector, SymmetricEigen};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The strategy's state over a box `[-1, 1]^n`, maximising.
#[derive(Debug, Clone)]
pub struct Cmaes {
    n: usize,
    lambda: usize,
    weights: Vec<f64>,
    mu_eff: f64,
    c_sigma: f64,
    d_sigma: f64,
    c_c: f64,
    c_1: f64,
    c_mu: f64,
    chi_n: f64,
    mean: DVector<f64>,
    sigma: f64,
    c: DMatrix<f64>,
    b: DMatrix<f64>,
    d: DVector<f64>,
    p_sigma: DVector<f64>,
    p_c: DVector<f64>,
    generation: u64,
    rng: ChaCha8Rng,
}

fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random_range(f64::EPSILON..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

impl Cmaes {
    /// A fresh strategy in `n` dimensions, centred in the box, σ₀ = 0.5.
    #[must_use]
    #[allow(clippy::cast_precision_loss)]
    pub fn new(n: usize, seed: u64) -> Self {
        let n = n.max(1);
        let nf = n as f64;
        let lambda = 4 + (3.0 * nf.ln()).floor() as usize;
        let mu = lambda / 2;
        let raw: Vec<f64> = (0..mu)
            .map(|i| ((lambda as f64 + 1.0) / 2.0).ln() - ((i + 1) as f64).ln())
            .collect();
        let sum: f64 = raw.iter().sum();
        let weights: Vec<f64> = raw.iter().map(|w| w / sum).collect();
        let mu_eff = 1.0 / weights.iter().map(|w| w * w).sum::<f64>();
        let c_sigma = (mu_eff + 2.0) / (nf + mu_eff + 5.0);
        let d_sigma = 1.0 + 2.0 * (((mu_eff - 1.0) / (nf + 1.0)).sqrt() - 1.0).max(0.0) + c_sigma;
        let c_c = (4.0 + mu_eff / nf) / (nf + 4.0 + 2.0 * mu_eff / nf);
        let c_1 = 2.0 / ((nf + 1.3).powi(2) + mu_eff);
        let c_mu =
            (1.0 - c_1).min(2.0 * (mu_eff - 2.0 + 1.0 / mu_eff) / ((nf + 2.0).powi(2) + mu_eff));
        Self {
            n,
            lambda,
            weights,
            mu_eff,
            c_sigma,
            d_sigma,
            c_c,
            c_1,
            c_mu,
            chi_n: nf.sqrt() * (1.0 - 1.0 / (4.0 * nf) + 1.0 / (21.0 * nf * nf)),
            mean: DVector::zeros(n),
            sigma: 0.5,
            c: DMatrix::identity(n, n),
            b: DMatrix::identity(n, n),
            d: DVector::from_element(n, 1.0),
            p_sigma: DVector::zeros(n),
            p_c: DVector::zeros(n),
            generation: 0,
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// Population size λ.
    #[must_use]
    pub fn lambda(&self) -> usize {
        self.lambda
    }

    /// A generation of λ candidates (unclamped; evaluate them clamped with [`Self::clamp`]).
    pub fn ask(&mut self) -> Vec<DVector<f64>> {
        (0..self.lambda)
            .map(|_| {
                let z = DVector::from_iterator(self.n, (0..self.n).map(|_| gauss(&mut self.rng)));
                let y = &self.b * z.component_mul(&self.d);
                &self.mean + y * self.sigma
            })
            .collect()
    }

    /// A point clamped into the box.
    #[must_use]
    pub fn clamp(x: &DVector<f64>) -> Vec<f64> {
        x.iter().map(|v| v.clamp(-1.0, 1.0)).collect()
    }

    /// Updates the distribution from the candidates of [`Self::ask`] and their
    /// fitness (higher is better).
    #[allow(clippy::cast_precision_loss)]
    pub fn tell(&mut self, candidates: &[DVector<f64>], fitness: &[f64]) {
        let mut order: Vec<usize> = (0..candidates.len().min(fitness.len())).collect();
        order.sort_by(|&a, &b| fitness[b].total_cmp(&fitness[a]));
        let ys: Vec<DVector<f64>> = order
            .iter()
            .take(self.weights.len())
            .map(|&i| (&candidates[i] - &self.mean) / self.sigma)
            .collect();
        let mut y_w = DVector::zeros(self.n);
        for (w, y) in self.weights.iter().zip(&ys) {
            y_w += y * *w;
        }
        self.mean += &y_w * self.sigma;
        // C^{-1/2} y_w = B D^{-1} Bᵀ y_w.
        let inv_sqrt = &self.b * (self.b.transpose() * &y_w).component_div(&self.d);
        self.p_sigma = &self.p_sigma * (1.0 - self.c_sigma)
            + inv_sqrt * (self.c_sigma * (2.0 - self.c_sigma) * self.mu_eff).sqrt();
        self.generation += 1;
        let norm = self.p_sigma.norm();
        let decay = (1.0 - (1.0 - self.c_sigma).powf(2.0 * self.generation as f64)).sqrt();
        let h_sigma = norm / decay < (1.4 + 2.0 / (self.n as f64 + 1.0)) * self.chi_n;
        let h = if h_sigma { 1.0 } else { 0.0 };
        self.p_c = &self.p_c * (1.0 - self.c_c)
            + &y_w * (h * (self.c_c * (2.0 - self.c_c) * self.mu_eff).sqrt());
        let mut rank_mu = DMatrix::zeros(self.n, self.n);
        for (w, y) in self.weights.iter().zip(&ys) {
            rank_mu += y * y.transpose() * *w;
        }
        let delta = (1.0 - h) * self.c_c * (2.0 - self.c_c);
        self.c = &self.c * (1.0 - self.c_1 - self.c_mu)
            + (&self.p_c * self.p_c.transpose() + &self.c * delta) * self.c_1
            + rank_mu * self.c_mu;
        self.sigma *= ((self.c_sigma / self.d_sigma) * (norm / self.chi_n - 1.0)).exp();
        // Keep σ within the box's scale (flat stretches of a noisy objective
        // can otherwise inflate it without bound).
        self.sigma = self.sigma.clamp(1e-8, 2.0);
        let c = (&self.c + self.c.transpose()) * 0.5;
        let eig = SymmetricEigen::new(c.clone());
        self.c = c;
        self.b = eig.eigenvectors;
        self.d = eig.eigenvalues.map(|v| v.max(1e-20).sqrt());
    }

    /// The recommendation: the distribution's mean, clamped into the box.
    #[must_use]
    pub fn recommend(&self) -> Vec<f64> {
        Self::clamp(&self.mean)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_maximum_of_a_noiseless_quadratic() {
        let target = [0.3, -0.5, 0.1];
        let f = |x: &[f64]| -> f64 {
            -x.iter()
                .zip(target)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
        };
        let mut es = Cmaes::new(3, 1);
        for _ in 0..200 {
            let cands = es.ask();
            let fit: Vec<f64> = cands.iter().map(|c| f(&Cmaes::clamp(c))).collect();
            es.tell(&cands, &fit);
        }
        let x = es.recommend();
        assert!(f(&x) > -1e-8, "{x:?}");
    }
}
