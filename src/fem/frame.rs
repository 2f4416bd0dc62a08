//! Inertial forces of a moving frame. The interior is simulated in the frame of the face's
//! node (the head's frame: the blend shapes, the bones and the skin's targets are fixed in
//! it), which moves rigidly in the world as x = Q(t) r + c(t). Newton's law in that frame
//! for a material point at r with velocity v reads
//!
//!   m a = F − m Q⁻¹ (Q̈ r + c̈) − 2 m Q⁻¹ Q̇ v,
//!
//! the frame's acceleration (its linear, angular and centripetal parts in one matrix Q⁻¹ Q̈)
//! and Coriolis. The field r ↦ Q⁻¹ (Q̈ r + c̈) is affine and the lattice's shape functions
//! reproduce affine fields exactly, so the consistent force on the nodes is −M a(q_a) with
//! a evaluated at each node. The derivatives are the backward differences over one time step
//! h, the accelerations backward Euler itself would see if the frame's motion were simulated
//! in the world: c̈ ≈ (c(t) − 2 c(t − h) + c(t − 2h)) / h².

use super::BackwardEuler;
use nalgebra::{Matrix3, Matrix4, Vector3};

/// The acceleration of a moving frame, expressed in the frame: a material point at rest at r
/// (m) in the frame has world acceleration Q (L r + b), and a point moving at v in the frame
/// adds the Coriolis term 2 Q S v.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameAcceleration {
    /// L = Q⁻¹ Q̈ (1/s²): angular acceleration and centripetal parts together.
    pub linear: Matrix3<f64>,
    /// b = Q⁻¹ c̈ (m/s²): the acceleration of the frame's origin.
    pub offset: Vector3<f64>,
    /// S = Q⁻¹ Q̇ (1/s): the angular velocity as a skew matrix (for a rigid frame).
    pub spin: Matrix3<f64>,
}

impl FrameAcceleration {
    /// The frame's acceleration over the time step that ends at `t` (s) of length `h` (s),
    /// from its affine motion `g` (world points of the frame at t = 0 to world points at t,
    /// metres): backward differences of G at t, t − h and t − 2h.
    pub fn of_motion(g: impl Fn(f64) -> Matrix4<f64>, t: f64, h: f64) -> Self {
        let (g0, g1, g2) = (g(t), g(t - h), g(t - 2.0 * h));
        let lin = |m: &Matrix4<f64>| m.fixed_view::<3, 3>(0, 0).into_owned();
        let off = |m: &Matrix4<f64>| Vector3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
        let q = lin(&g0);
        let qi = q.try_inverse().unwrap_or_else(Matrix3::identity);
        let qdd = (q - 2.0 * lin(&g1) + lin(&g2)) / (h * h);
        let cdd = (off(&g0) - 2.0 * off(&g1) + off(&g2)) / (h * h);
        let qd = (q - lin(&g1)) / h;
        Self {
            linear: qi * qdd,
            offset: qi * cdd,
            spin: qi * qd,
        }
    }

    /// Frame acceleration a(r) = L r + b of a point at rest at `r` in the frame (m/s²).
    pub fn at(&self, r: &Vector3<f64>) -> Vector3<f64> {
        self.linear * r + self.offset
    }

    /// Whether the frame is at rest (no force to apply).
    pub fn is_zero(&self) -> bool {
        self.linear.norm() == 0.0 && self.offset.norm() == 0.0 && self.spin.norm() == 0.0
    }
}

impl BackwardEuler {
    /// The inertial force of the moving frame `acc` on the nodes at the stepper's current
    /// positions and velocities (flat, N): −M (a(q) + 2 S v). Taken at the start of a step
    /// (explicit in q and v): the frame's terms are slow against the flesh's own modes.
    pub fn frame_force(&self, acc: &FrameAcceleration) -> Vec<f64> {
        let mut a = vec![0.0; self.q.len()];
        for ((o, q), v) in a
            .chunks_exact_mut(3)
            .zip(self.q.chunks_exact(3))
            .zip(self.v.chunks_exact(3))
        {
            let r = Vector3::new(q[0], q[1], q[2]);
            let vel = Vector3::new(v[0], v[1], v[2]);
            let x = acc.at(&r) + 2.0 * acc.spin * vel;
            o.copy_from_slice(x.as_slice());
        }
        let mut f = self.mass_times(&a);
        f.iter_mut().for_each(|x| *x = -*x);
        f
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Translation3};

    /// A frame turning about y at constant angular acceleration α from rest, its origin at
    /// d from the axis: L = Qᵀ Q̈ = α [ω̂] + ω² [ω̂]² (angular and centripetal).
    #[test]
    fn turning_frame_has_angular_and_centripetal_acceleration() {
        let alpha = 3.0;
        let g = |t: f64| {
            let th = 0.5 * alpha * t.max(0.0) * t.max(0.0);
            let r = Rotation3::from_axis_angle(&Vector3::y_axis(), th);
            (Translation3::new(0.0, 0.0, 0.0) * r).to_homogeneous()
        };
        let (t, h) = (0.7, 1e-4);
        let acc = FrameAcceleration::of_motion(g, t, h);
        let w = alpha * t;
        let k = Vector3::y().cross_matrix();
        let want = alpha * k + w * w * k * k;
        assert!((acc.linear - want).norm() < 1e-2 * want.norm(), "{acc:?}");
        assert!((acc.spin - w * k).norm() < 1e-3 * w, "{:?}", acc.spin);
        // A point at r = (0, 0, 1): tangential α along +x, centripetal ω² towards the axis.
        let a = acc.at(&Vector3::z());
        assert!((a - Vector3::new(alpha, 0.0, -w * w)).norm() < 1e-2 * w * w);
    }

    #[test]
    fn translating_frame_has_its_origin_acceleration() {
        let g = |t: f64| Translation3::new(0.5 * 2.0 * t * t, 0.0, 0.0).to_homogeneous();
        let acc = FrameAcceleration::of_motion(g, 1.0, 0.01);
        assert!((acc.offset - Vector3::new(2.0, 0.0, 0.0)).norm() < 1e-9);
        assert!(acc.linear.norm() < 1e-9 && acc.spin.norm() < 1e-9);
        assert!(!acc.is_zero());
        let still = FrameAcceleration::of_motion(|_| Matrix4::identity(), 1.0, 0.01);
        assert!(still.is_zero());
    }
}
