//! Forward kinematics of a [`NaoModel`] in f64: where every body is for a set
//! of joint angles. Used to place the robot before a simulation, to weld the
//! upper body, and to check the walk's inverse kinematics.
//!
//! A body's *motion* `G_b` is the rigid transform that carries it from the
//! zero pose (every frame aligned with the torso's) to its posed place; a
//! point attached to body `b` at zero-pose coordinates `p` is then at `G_b·p`.

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

use super::model::{NaoModel, Shape};

/// A rigid transform, f64.
pub type Iso = Isometry3<f64>;

/// For each body, the index of the joint whose child it is (None for the torso).
#[must_use]
pub fn parent_joints(model: &NaoModel) -> Vec<Option<usize>> {
    let mut out = vec![None; model.bodies.len()];
    for (j, joint) in model.joints.iter().enumerate() {
        out[joint.child] = Some(j);
    }
    out
}

/// The rotation of one hinge by `q` about its zero-pose axis through its anchor.
#[must_use]
pub fn hinge_motion(anchor: [f64; 3], axis: [f64; 3], q: f64) -> Iso {
    let a = Vector3::from(anchor);
    let r = UnitQuaternion::from_axis_angle(&Unit::new_normalize(Vector3::from(axis)), q);
    Translation3::from(a) * r * Translation3::from(-a)
}

/// Every body's motion for joint angles `angles` (one per model joint, rad)
/// and the torso's motion `root`.
///
/// # Panics
/// If `angles` has fewer entries than the model has joints (a programming error).
#[must_use]
pub fn body_motions(model: &NaoModel, angles: &[f64], root: &Iso) -> Vec<Iso> {
    assert!(angles.len() >= model.joints.len(), "one angle per joint");
    let pj = parent_joints(model);
    let mut g: Vec<Iso> = Vec::with_capacity(model.bodies.len());
    for (i, _) in model.bodies.iter().enumerate() {
        let m = match pj[i] {
            None => *root,
            Some(j) => {
                let joint = &model.joints[j];
                // validate() guarantees parents come first.
                g[joint.parent] * hinge_motion(joint.anchor, joint.axis, angles[j])
            }
        };
        g.push(m);
    }
    g
}

/// Where a zero-pose point attached to a body is after its motion.
#[must_use]
pub fn moved(g: &Iso, p: [f64; 3]) -> [f64; 3] {
    let q = g * Point3::from(p);
    [q.x, q.y, q.z]
}

/// The lowest z of any collision shape for these motions (box corners, sphere
/// and capsule bottoms), m.
#[must_use]
pub fn lowest_point(model: &NaoModel, motions: &[Iso]) -> f64 {
    let mut low = f64::INFINITY;
    for (b, g) in model.bodies.iter().zip(motions) {
        if !b.collider {
            continue;
        }
        match b.shape {
            Shape::Box { half } => {
                for sx in [-1.0, 1.0] {
                    for sy in [-1.0, 1.0] {
                        for sz in [-1.0, 1.0] {
                            let p = [
                                b.centre[0] + sx * half[0],
                                b.centre[1] + sy * half[1],
                                b.centre[2] + sz * half[2],
                            ];
                            low = low.min(moved(g, p)[2]);
                        }
                    }
                }
            }
            Shape::Sphere { radius } => low = low.min(moved(g, b.centre)[2] - radius),
            Shape::Capsule {
                radius,
                half_length,
            } => {
                let axis = g.rotation * Vector3::z();
                let c = moved(g, b.centre)[2];
                low = low.min(c - half_length * axis.z.abs() - radius);
            }
        }
    }
    low
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nao::model::Morphology;

    #[test]
    fn zero_pose_is_identity_and_anchors_stay_on_both_bodies() {
        let m = NaoModel::new(Morphology::of_type(4).unwrap()).unwrap();
        let zero = vec![0.0; m.joints.len()];
        for g in body_motions(&m, &zero, &Iso::identity()) {
            assert!((g.translation.vector.norm()) < 1e-15);
        }
        // At any pose, a joint's anchor moves identically with parent and child.
        let q: Vec<f64> = (0..m.joints.len()).map(|i| 0.1 * i as f64 - 0.7).collect();
        let g = body_motions(&m, &q, &Iso::identity());
        for j in &m.joints {
            let a = moved(&g[j.parent], j.anchor);
            let b = moved(&g[j.child], j.anchor);
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() < 1e-12, "{}", j.name);
            }
        }
    }

    #[test]
    fn standing_sole_is_hip_to_sole_below_the_hip() {
        let m = NaoModel::new(Morphology::of_type(0).unwrap()).unwrap();
        let zero = vec![0.0; m.joints.len()];
        let low = lowest_point(&m, &body_motions(&m, &zero, &Iso::identity()));
        assert!((low + m.torso_height_standing()).abs() < 1e-12);
    }
}
