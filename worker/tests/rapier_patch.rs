//! The vendored rapier3d's own changes beyond the release's (vendor/rapier3d/
//! NAOFARM.md): what the release left as stubs now works. naofarm's NAO
//! uses hinges only, so these paths are checked here on their own; the
//! slice kernels that do nalgebra's arithmetic faster give its bits; the
//! tree's factorisation solves as the dense inverse does. One fault of the
//! release that the walk leans on is pinned as docs/walk.md describes it.

use rapier3d::math::Vector;
use rapier3d::prelude::*;
use rapier3d::utils::CrossProduct;

/// A pendulum on a multibody joint with the angular axes `free` free (every
/// linear axis locked), its bob's centre at `bob` below-and-beside the pivot
/// at the origin; runs `steps` steps of 5 ms and returns, per step, the
/// bob's centre, its angular velocity and the joint's coordinates.
fn pendulum(
    free: JointAxesMask,
    limit_x: Option<[f32; 2]>,
    bob: Vector,
    steps: usize,
) -> Vec<(Vector, Vector, [f32; 6])> {
    let mut world = PhysicsWorld::new();
    world.gravity = Vector::new(0.0, 0.0, -9.81);
    world.integration_parameters.dt = 0.005;
    let base = world.bodies.insert(RigidBodyBuilder::fixed());
    let link = world
        .bodies
        .insert(RigidBodyBuilder::dynamic().translation(bob));
    world.colliders.insert_with_parent(
        ColliderBuilder::ball(0.03).density(1000.0),
        link,
        &mut world.bodies,
    );
    let mut joint = GenericJointBuilder::new(JointAxesMask::all() - free)
        .local_anchor1(Vector::ZERO)
        .local_anchor2(-bob);
    if let Some(l) = limit_x {
        joint = joint.limits(JointAxis::AngX, l);
    }
    let handle = world
        .multibody_joints
        .insert(base, link, joint, true)
        .expect("a tree");
    (0..steps)
        .map(|_| {
            world.step();
            let rb = &world.bodies[link];
            let (mb, id) = world.multibody_joints.get(handle).expect("the joint");
            let c = mb.link(id).expect("the link").joint().coords();
            (
                rb.translation(),
                rb.angvel(),
                [c[0], c[1], c[2], c[3], c[4], c[5]],
            )
        })
        .collect()
}

#[test]
fn a_multibody_joint_with_two_free_angular_axes_swings_about_those_two_only() {
    let bob = Vector::new(0.05, 0.08, -0.3);
    let run = pendulum(JointAxesMask::ANG_X | JointAxesMask::ANG_Y, None, bob, 400);
    // Gravity on the offset bob turns it about x and y: both coordinates move.
    let swing = |k: usize| run.iter().map(|r| r.2[k].abs()).fold(0.0f32, f32::max);
    assert!(
        swing(3) > 0.1 && swing(4) > 0.1,
        "x {} y {}",
        swing(3),
        swing(4)
    );
    assert_eq!(swing(5), 0.0, "the locked z coordinate moved");
    for (centre, angvel, _) in &run {
        assert!(centre.is_finite() && angvel.is_finite());
        // The parent is fixed with its joint frame on the world's axes, so
        // the bob's angular velocity is the joint's: none about z.
        assert!(
            angvel.z.abs() <= 1e-4 * angvel.length().max(1.0),
            "spin about the locked axis: {angvel:?}"
        );
        // The pivot holds: the bob stays on its sphere about the origin.
        assert!((centre.length() - bob.length()).abs() < 1e-3, "{centre:?}");
        // A pendulum gains no energy: the bob never rises above its start.
        assert!(centre.z <= bob.z + 1e-3, "rose to {}", centre.z);
    }
}

#[test]
fn a_two_free_axis_joint_keeps_the_limit_of_each_axis() {
    let bob = Vector::new(0.05, 0.08, -0.3);
    let run = pendulum(
        JointAxesMask::ANG_X | JointAxesMask::ANG_Y,
        Some([-0.1, 0.1]),
        bob,
        400,
    );
    let x = run.iter().map(|r| r.2[3].abs()).fold(0.0f32, f32::max);
    let y = run.iter().map(|r| r.2[4].abs()).fold(0.0f32, f32::max);
    assert!(x <= 0.1 + 0.02, "x went to {x} past its 0.1 rad stop");
    assert!(y > 0.1, "y, without a limit, swung only {y}");
}

#[test]
fn a_scalar_crosses_a_3d_vector_as_an_angular_velocity_about_z() {
    // The 2D meaning of a scalar angular quantity, s·ẑ × v.
    let v = Vector::new(1.0, 2.0, 3.0);
    assert_eq!(2.0f32.gcross(v), Vector::new(-4.0, 2.0, 0.0));
    assert_eq!(
        2.0f32.gcross(v),
        Vector::new(0.0, 0.0, 2.0).cross(Vector::new(1.0, 2.0, 0.0))
    );
    let n = rapier3d::na::Vector3::new(1.0f32, 2.0, 3.0);
    assert_eq!(2.0f32.gcross(n), rapier3d::na::Vector3::new(-4.0, 2.0, 0.0));
}

/// A well-conditioned `n × n` matrix with every entry set, whose LU
/// factorisation pivots.
fn pivoting_matrix(n: usize) -> nalgebra::DMatrix<f32> {
    nalgebra::DMatrix::from_fn(n, n, |i, j| {
        let x = ((i * 7 + j * 13) % 17) as f32 / 17.0 - 0.5;
        if i == (j + 3) % n {
            x + n as f32
        } else {
            x
        }
    })
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// Solves `b` with nalgebra's LU and with the slice kernel; asserts the
/// same bits, naming `what`.
fn solves_alike(
    lu: &nalgebra::LU<f32, nalgebra::Dyn, nalgebra::Dyn>,
    b: nalgebra::DVector<f32>,
    what: &str,
) {
    let (mut theirs, mut ours) = (b.clone(), b);
    assert!(lu.solve_mut(&mut theirs));
    rapier3d::utils::slice_blas::lu_solve(lu, ours.as_mut_slice());
    assert_eq!(bits(ours.as_slice()), bits(theirs.as_slice()), "{what}");
}

#[test]
fn the_slice_kernels_give_nalgebras_bits() {
    use rapier3d::utils::slice_blas::{axpy, solve_upper};
    for n in [1, 2, 7, 24, 32] {
        let lu = nalgebra::LU::new(pivoting_matrix(n));
        // Every column of M⁻¹, as the motor and stop rows ask for it.
        let mut moved = 0;
        for k in 0..n {
            let mut unit = nalgebra::DVector::<f32>::zeros(n);
            unit[k] = 1.0;
            solves_alike(&lu, unit, &format!("n {n}, column {k}"));
            let mut permuted = nalgebra::DVector::<f32>::zeros(n);
            permuted[k] = 1.0;
            lu.p().permute_rows(&mut permuted);
            moved += usize::from(permuted[k] != 1.0);
        }
        // The matrices pivot, so the forward substitution starts elsewhere
        // than at k for some columns.
        assert!(n < 7 || moved > 0, "n {n}: no column was moved");
        // A contact's row: zeros where it moves no degree of freedom (from
        // none to all but the last), with and without a −0 among them.
        for first in 0..n {
            for negative_zero in [None, Some(n - 1 - first / 2)] {
                let mut b = nalgebra::DVector::<f32>::from_fn(n, |i, _| {
                    if i < first || i % 3 == 1 {
                        0.0
                    } else {
                        (i as f32 * 0.53).sin() - 0.2
                    }
                });
                if let Some(z) = negative_zero {
                    b[z] = -0.0;
                }
                let what = format!("n {n}, zeros before {first}, -0 at {negative_zero:?}");
                solves_alike(&lu, b, &what);
            }
        }
        // A dense right-hand side through the upper triangle.
        let u = lu.u();
        let b = nalgebra::DVector::<f32>::from_fn(n, |i, _| (i as f32 * 0.37).sin() + 0.1);
        let mut theirs = b.clone();
        let mut ours = b.clone();
        assert!(u.solve_upper_triangular_mut(&mut theirs));
        assert!(solve_upper(&u, ours.as_mut_slice()));
        assert_eq!(bits(ours.as_slice()), bits(theirs.as_slice()), "n {n}");
        // And y ← a·x + y.
        let x = nalgebra::DVector::<f32>::from_fn(n, |i, _| (i as f32 * 0.11).cos() * 1e3);
        theirs.axpy(-0.3, &x, 1.0);
        axpy(ours.as_mut_slice(), -0.3, x.as_slice());
        assert_eq!(bits(ours.as_slice()), bits(theirs.as_slice()), "n {n}");
    }
    // A zero on the diagonal stops both solves alike.
    let mut singular = pivoting_matrix(4).upper_triangle();
    singular[(2, 2)] = 0.0;
    let b = nalgebra::DVector::<f32>::from_element(4, 1.0);
    let (mut theirs, mut ours) = (b.clone(), b);
    assert!(!singular.solve_upper_triangular_mut(&mut theirs));
    assert!(!solve_upper(&singular, ours.as_mut_slice()));
    assert_eq!(bits(ours.as_slice()), bits(theirs.as_slice()));
}

use rapier3d::utils::tree_ldl::{TreeLdl, NO_PARENT};

/// A random symmetric positive-definite matrix with the pattern of the tree
/// `parents`: `I + Σ_k J_k J_kᵀ`, each `J_k` nonzero on `k`'s chain only.
fn tree_matrix(parents: &[usize], seed: u32) -> nalgebra::DMatrix<f32> {
    let n = parents.len();
    let mut s = seed;
    let mut next = || {
        s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (s >> 8) as f32 / (1u32 << 24) as f32 - 0.5
    };
    let mut h = nalgebra::DMatrix::identity(n, n);
    for k in 0..n {
        let mut j = nalgebra::DVector::zeros(n);
        let mut i = k;
        while i != NO_PARENT {
            j[i] = next();
            i = parents[i];
        }
        h += &j * j.transpose();
    }
    h
}

#[test]
fn the_trees_factorisation_solves_as_the_dense_inverse_does() {
    // A free root (6 in a row), two branches off its end, a fork off the
    // first branch's end and a second child of its middle.
    let parents = [NO_PARENT, 0, 1, 2, 3, 4, 5, 6, 7, 5, 9, 10, 11, 8, 13, 7];
    for seed in 0..5 {
        let h = tree_matrix(&parents, seed);
        // Entries off the pattern are zero; the factorisation never reads them.
        assert_eq!(h[(8, 9)], 0.0);
        let ldl = TreeLdl::factor(&h, &parents).expect("positive definite");
        assert_eq!(ldl.dim(), parents.len());
        let inv = h.clone().try_inverse().expect("invertible");
        for k in 0..parents.len() {
            let mut x = vec![0.0; parents.len()];
            x[k] = 1.0;
            x[(k + 3) % parents.len()] = -0.5;
            ldl.solve(&mut x);
            for (i, xi) in x.iter().enumerate() {
                let want = inv[(i, k)] - 0.5 * inv[(i, (k + 3) % parents.len())];
                assert!(
                    (xi - want).abs() < 1.0e-4,
                    "seed {seed}, rhs {k}, row {i}: {xi} vs {want}"
                );
            }
        }
    }
}

#[test]
fn the_trees_factorisation_refuses_a_matrix_that_is_not_positive_definite() {
    let h = nalgebra::DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
    assert!(TreeLdl::factor(&h, &[NO_PARENT, 0]).is_none());
    let h = nalgebra::DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, f32::NAN]);
    assert!(TreeLdl::factor(&h, &[NO_PARENT, 0]).is_none());
}

/// A free chain like a NAO leg (no gravity, no motors, no stops): a torso of
/// 1.2 kg, then light 0.07 kg connectors between 0.3–0.4 kg links, spinning.
/// With `torque`, each link but the root carries a constant 1 mN·m about z
/// every step. Returns the bodies' linear momentum at the start of the
/// second step and after 0.2 s of 0.2 ms steps.
fn free_chain_momentum(torque: bool) -> (Vector, Vector) {
    let mut world = PhysicsWorld::new();
    world.gravity = Vector::ZERO;
    world.integration_parameters.dt = 0.0002;
    let specs: [(f32, f32, f32); 5] = [
        (1.2, 0.01, 0.0),
        (0.07, 2.8e-6, -0.05),
        (0.39, 1.0e-3, -0.10),
        (0.07, 2.8e-6, -0.15),
        (0.3, 1.0e-3, -0.20),
    ];
    let bodies: Vec<RigidBodyHandle> = specs
        .iter()
        .map(|(m, i, z)| {
            world.bodies.insert(
                RigidBodyBuilder::dynamic()
                    .translation(Vector::new(0.0, 0.0, 10.0 + z))
                    .can_sleep(false)
                    .additional_mass_properties(MassProperties::new(
                        Vector::ZERO,
                        *m,
                        Vector::new(*i, *i, *i),
                    )),
            )
        })
        .collect();
    let axes = [Vector::Z, Vector::X, Vector::Y, Vector::Y];
    let mut root = None;
    for (k, axis) in axes.iter().enumerate() {
        let joint = RevoluteJointBuilder::new(*axis)
            .local_anchor1(Vector::new(0.0, 0.0, -0.025))
            .local_anchor2(Vector::new(0.0, 0.0, 0.025));
        let h = world
            .multibody_joints
            .insert(bodies[k], bodies[k + 1], joint, true);
        root = root.or(h);
    }
    let (mb, _) = world
        .multibody_joints
        .get_mut(root.expect("a multibody"))
        .expect("the multibody");
    let n = mb.ndofs();
    let mut v = mb.generalized_velocity_mut();
    v[3] = 0.3;
    v[4] = -0.2;
    v[5] = 0.5;
    for k in 6..n {
        v[k] = ((k - 5) as f32 * 0.7).sin() * 2.0;
    }
    let momentum = |world: &PhysicsWorld| {
        bodies.iter().fold(Vector::ZERO, |p, h| {
            let rb = &world.bodies[*h];
            p + rb.linvel() * rb.mass()
        })
    };
    let mut first = Vector::ZERO;
    for step in 0..1000 {
        if step == 1 {
            first = momentum(&world);
        }
        for h in &bodies[1..] {
            let rb = &mut world.bodies[*h];
            rb.reset_forces(false);
            if torque {
                rb.add_torque(Vector::new(0.0, 0.0, 0.001), false);
            }
        }
        world.step();
    }
    (first, momentum(&world))
}

/// A pure torque cannot change a free body's linear momentum; on the
/// multibody's links it does (rapier3d 0.36.1 as released does the same).
/// docs/walk.md ("The links' drag, and the step") says what this does to
/// the walk: if this test fails, rapier maps a link's torque right and
/// that section, and the balance tuned with the fault, are to be revisited.
#[test]
fn a_torque_on_a_multibody_link_moves_the_chains_momentum_as_documented() {
    let (p0, p1) = free_chain_momentum(false);
    let drift = (p1 - p0).length() / p0.length();
    println!("momentum drift untouched: {drift}");
    assert!(
        drift < 3e-4,
        "untouched, the chain keeps its momentum: {drift}"
    );
    let (p0, p1) = free_chain_momentum(true);
    let drift = (p1 - p0).length() / p0.length();
    println!("momentum drift with the torques: {drift}");
    assert!(
        drift > 3e-3,
        "torques on the links moved the momentum by {drift}"
    );
}
