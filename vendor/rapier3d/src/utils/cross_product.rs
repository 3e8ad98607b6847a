//! SimdCross trait for generalized cross product.

use crate::math::{Real, Vector};
#[cfg(not(target_arch = "spirv"))]
use na::{Vector2, Vector3};
#[cfg(not(target_arch = "spirv"))]
use simba::simd::SimdRealField;

/// Trait for computing generalized cross products.
pub trait CrossProduct<Rhs>: Sized {
    /// The result type of the cross product.
    type Result;
    /// Computes the generalized cross product of `self` with `rhs`.
    fn gcross(&self, rhs: Rhs) -> Self::Result;
}

#[cfg(not(target_arch = "spirv"))]
impl<T: SimdRealField + Copy> CrossProduct<Vector3<T>> for Vector3<T> {
    type Result = Self;

    fn gcross(&self, rhs: Vector3<T>) -> Self::Result {
        self.cross(&rhs)
    }
}

#[cfg(not(target_arch = "spirv"))]
impl<T: SimdRealField + Copy> CrossProduct<Vector2<T>> for Vector2<T> {
    type Result = T;

    fn gcross(&self, rhs: Vector2<T>) -> Self::Result {
        self.x * rhs.y - self.y * rhs.x
    }
}

#[cfg(not(target_arch = "spirv"))]
impl<T: SimdRealField + Copy> CrossProduct<Vector2<T>> for T {
    type Result = Vector2<T>;

    fn gcross(&self, rhs: Vector2<T>) -> Self::Result {
        Vector2::new(-rhs.y * *self, rhs.x * *self)
    }
}

// naofarm: the release left the two impls below as stubs that panic
// (the trait bound `ScalarType` needs them; rapier3d never calls
// them). They now mean what a scalar angular quantity means in 2D: the
// scalar s is the angular vector s·ẑ, so s × v = (−s·v.y, s·v.x, 0), the 2D
// formula with a zero z.
#[cfg(not(target_arch = "spirv"))]
impl<T: SimdRealField + Copy> CrossProduct<Vector3<T>> for T {
    type Result = Vector3<T>;

    fn gcross(&self, rhs: Vector3<T>) -> Self::Result {
        Vector3::new(-rhs.y * *self, rhs.x * *self, T::zero())
    }
}

#[cfg(feature = "dim3")]
impl CrossProduct<Vector> for Real {
    type Result = Vector;

    fn gcross(&self, rhs: Vector) -> Self::Result {
        Vector::new(-rhs.y * *self, rhs.x * *self, 0.0)
    }
}

// Glam implementations for concrete Vector type
#[cfg(feature = "dim3")]
impl CrossProduct<Vector> for Vector {
    type Result = Vector;

    fn gcross(&self, rhs: Vector) -> Self::Result {
        self.cross(rhs)
    }
}

#[cfg(feature = "dim2")]
impl CrossProduct<Vector> for Vector {
    type Result = Real;

    fn gcross(&self, rhs: Vector) -> Self::Result {
        self.x * rhs.y - self.y * rhs.x
    }
}

#[cfg(feature = "dim2")]
impl CrossProduct<Vector> for Real {
    type Result = Vector;

    fn gcross(&self, rhs: Vector) -> Self::Result {
        Vector::new(-rhs.y * *self, rhs.x * *self)
    }
}
