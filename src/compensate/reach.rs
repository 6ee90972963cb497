//! The reach bound: a ball that certainly holds T, so that a Cartesian
//! target beyond it is answered unreachable at once instead of costing
//! every seed a full solve, and so that a frozen solve can be told apart
//! from a slow one (`super::solve`).

use nalgebra::{Matrix3, Rotation3, Vector3};

use crate::kinematics::JointParam;
use crate::kinematics::chain::Chain;
use crate::model::Convention;

use super::Compensator;

/// A ball that holds T for every joint angle (limits ignored): a true upper
/// bound on the arm's reach, for either convention, tool point included.
///
/// Every joint is revolute and only `a`, `d` and the tool point translate,
/// so the arm is a chain of rigid segments, each joining a point on one
/// joint axis to a point on the next (the last one joins it to T); a joint
/// turns everything after its axis without moving the axis. Each segment
/// keeps its length whatever the joints, so T is never farther from the
/// first point (on joint 1's axis, fixed in the base frame) than the sum of
/// the lengths, by the triangle inequality.
///
/// - DH, `Rz(q+θ) Tz(d) Tx(a) Rx(α) Ry(β)`: the points are `P_j = o_j +
///   d_{j+1} z_j` (on axis j+1, which is `z_j`), from `P_0 = (0, 0, d_1)`;
///   `P_j - P_{j-1} = R (a_j x + Rx(α_j) Ry(β_j) d_{j+1} z)` with `R =
///   R_{j-1} Rz(q_j + θ_j)` a rotation, and `T - P_{n-1} = R (a_n x +
///   Rx(α_n) Ry(β_n) tool) = R_n ((Rx(α_n) Ry(β_n))ᵀ a_n x + tool)`.
/// - MDH, `Rx(α) Ry(β) Tx(a) Rz(q+θ) Tz(d)`: the points are the frame
///   origins `o_j` (on axis j), from `o_1 = Rx(α_1) Ry(β_1) (a_1, 0, d_1)`;
///   `|o_j - o_{j-1}| = sqrt(a_j² + d_j²)` and `T - o_n = R_n tool`.
///
/// With the flange orientation `R_n` given, the last segment is fixed too:
/// its start, `T - R_n last`, is within `radius - |last|` of the centre.
///
/// The same sums bound the distance from T to any joint axis (the segments
/// after that axis), so they also bound how fast T moves as a joint turns:
/// at most `radius` mm per radian.
#[derive(Debug, Clone, Copy)]
pub(super) struct Reach {
    pub(super) centre: Vector3<f64>,
    pub(super) radius: f64,
    /// The last segment in the flange frame: from the point on the last
    /// joint's axis to T.
    pub(super) last: Vector3<f64>,
}

impl Reach {
    pub(super) fn of(chain: &Chain, p: &[f64]) -> Reach {
        let l = chain.layout;
        let n = l.n_joints;
        let t = l.tool();
        let tool = Vector3::new(p[t], p[t + 1], p[t + 2]);
        let at = |j: usize, k: JointParam| p[l.joint(j, k)];
        let twist = |j: usize| {
            Rotation3::from_axis_angle(&Vector3::x_axis(), at(j, JointParam::Alpha))
                * Rotation3::from_axis_angle(&Vector3::y_axis(), at(j, JointParam::Beta))
        };
        let a_x = |j: usize| Vector3::new(at(j, JointParam::A), 0.0, 0.0);
        if n == 0 {
            return Reach {
                centre: Vector3::zeros(),
                radius: tool.norm(),
                last: tool,
            };
        }
        match chain.convention {
            Convention::Dh => {
                let last = twist(n - 1).inverse() * a_x(n - 1) + tool;
                Reach {
                    centre: Vector3::new(0.0, 0.0, at(0, JointParam::D)),
                    radius: (0..n - 1)
                        .map(|j| {
                            let d_next = Vector3::new(0.0, 0.0, at(j + 1, JointParam::D));
                            (a_x(j) + twist(j) * d_next).norm()
                        })
                        .sum::<f64>()
                        + last.norm(),
                    last,
                }
            }
            Convention::Mdh => Reach {
                centre: twist(0) * Vector3::new(at(0, JointParam::A), 0.0, at(0, JointParam::D)),
                radius: (1..n)
                    .map(|j| at(j, JointParam::A).hypot(at(j, JointParam::D)))
                    .sum::<f64>()
                    + tool.norm(),
                last: tool,
            },
        }
    }

    /// How far `point` is outside a ball of `radius` about the centre (mm;
    /// negative inside), less a rounding allowance, so that a positive
    /// answer is out of reach for sure.
    fn outside(&self, point: &Vector3<f64>, radius: f64) -> f64 {
        let d = (point - self.centre).norm();
        d - radius - 1e-9 * (d + self.radius + self.centre.norm())
    }

    /// How far T at `point` is out of reach for any joints (mm; negative
    /// when it may be within reach).
    pub(super) fn beyond(&self, point: &Vector3<f64>) -> f64 {
        self.outside(point, self.radius)
    }

    /// The same for T at `point` with the flange at `rot` (to within
    /// `tolerance_rad`): how far the start of the last segment is out of
    /// the reach of the others, and where it is.
    pub(super) fn beyond_pose(
        &self,
        point: &Vector3<f64>,
        rot: &Matrix3<f64>,
        tolerance_rad: f64,
    ) -> (f64, Vector3<f64>) {
        let start = point - rot * self.last;
        let len = self.last.norm();
        // The flange may turn by `tolerance_rad`: the start moves as much
        // times the segment's length.
        let slack = tolerance_rad * len;
        (self.outside(&start, self.radius - len) - slack, start)
    }
}

impl Compensator {
    /// Where the calibrated arm's T can be, whatever the joints.
    pub(super) fn reach_calibrated(&self) -> &Reach {
        self.reach_calibrated
            .get_or_init(|| Reach::of(&self.chain, &self.calibrated.values))
    }
}
