//! Inverse kinematics: closed forms where the arm has one (the IRp-6), damped least squares with
//! joint limits and seeded restarts for any arm.

mod irp6;

pub(crate) use irp6::IRP6_DH;

use std::f64::consts::TAU;

use nalgebra::{Isometry3, Matrix6, Matrix6xX, Vector6};

use crate::error::ModelError;
use crate::joint::{JointKind, JointLimits};
use crate::rng::Rng;
pub use crate::robot::ClosedForm;
use crate::robot::{ArmChain, Robot};

/// Largest position (m) and angle (rad) error a closed-form solution may show when checked by
/// forward kinematics; above it the solution is dropped (a numerical edge, never expected).
const CLOSED_FORM_CHECK: f64 = 1e-9;

/// Bring an angle into `limits` by whole turns, choosing the copy nearest `near`; `None` when no
/// copy lies within the limits.
fn turn_into(value: f64, limits: &JointLimits, near: f64) -> Option<f64> {
    let slack = 1e-12;
    let base = value + TAU * ((near - value) / TAU).round();
    [base, base - TAU, base + TAU, base - 2.0 * TAU, base + 2.0 * TAU]
        .into_iter()
        .filter(|v| (limits.lower - slack..=limits.upper + slack).contains(v))
        .min_by(|a, b| (a - near).abs().total_cmp(&(b - near).abs()))
        .map(|v| limits.clamp(v))
}

/// Settings of [`Robot::inverse_kinematics`].
#[derive(Debug, Clone)]
pub struct IkOptions {
    /// Position tolerance, metres.
    pub position_tolerance: f64,
    /// Orientation tolerance, radians.
    pub orientation_tolerance: f64,
    /// Iterations per attempt.
    pub max_iterations: usize,
    /// Attempts from random seeds after the first (from the given seed).
    pub restarts: usize,
    /// Damping of the least-squares step.
    pub damping: f64,
    /// Seed of the restart generator (deterministic).
    pub seed: u64,
    /// Solve for position only (3 DOF task), ignoring orientation.
    pub position_only: bool,
    /// Answer from the end effector's closed form when it has one covering every joint that
    /// moves it (default); `false` always uses the numerical solver.
    pub closed_form: bool,
}

impl Default for IkOptions {
    fn default() -> Self {
        Self {
            position_tolerance: 1e-6,
            orientation_tolerance: 1e-6,
            max_iterations: 100,
            restarts: 20,
            damping: 1e-4,
            seed: 0x1c0ffee,
            position_only: false,
            closed_form: true,
        }
    }
}

/// 6D pose error (position; orientation as rotation vector), both in the world frame.
pub fn pose_error(current: &Isometry3<f64>, target: &Isometry3<f64>) -> Vector6<f64> {
    let dp = target.translation.vector - current.translation.vector;
    let dr = (target.rotation * current.rotation.inverse()).scaled_axis();
    Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z)
}

impl Robot {
    /// A seed's checks: its length, finiteness and joint limits (a seed out of a screw's stroke
    /// is still a place to start from; solutions keep within the strokes).
    fn check_joint_configuration(&self, seed: &[f64]) -> Result<(), ModelError> {
        match self.check_configuration(seed) {
            Err(ModelError::OutOfStroke { .. }) => Ok(()),
            other => other,
        }
    }

    /// The closed form attached to end effector `ee`, if it has one.
    pub fn closed_form(&self, ee: usize) -> Option<ClosedForm> {
        self.closed_forms.get(ee).and_then(|c| c.as_ref()).map(|c| c.kind)
    }

    /// Every configuration placing end effector `ee`'s tool frame at `target` within the joint
    /// limits, from the end effector's closed form, nearest to `seed` first (configuration-space
    /// distance). Joints outside the arm (a track) keep their `seed` values; each arm angle is
    /// the whole-turn copy within its limits nearest the seed's. An empty list means the pose is
    /// out of reach or every solution breaks a limit. Each solution is checked by forward
    /// kinematics to 1e-9 m and rad.
    ///
    /// Errors: no such end effector, an invalid seed, or no closed form for this end effector
    /// ([`ModelError::NoClosedForm`]; use [`Robot::inverse_kinematics`]).
    pub fn inverse_kinematics_all(
        &self,
        ee: usize,
        target: &Isometry3<f64>,
        seed: &[f64],
    ) -> Result<Vec<Vec<f64>>, ModelError> {
        let effector = self.end_effector_checked(ee)?;
        self.check_joint_configuration(seed)?;
        let Some(chain) = self.closed_forms.get(ee).and_then(|c| c.as_ref()) else {
            return Err(ModelError::NoClosedForm { robot: self.name().to_string(), frame: effector.name.clone() });
        };
        let shoulder = self.link_pose(seed, chain.shoulder_link) * chain.shoulder;
        let flange = shoulder.inv_mul(&(target * effector.tool.inverse()));
        let arm_seed = chain.dofs.map(|d| seed[d]);
        let limits = self.limits();
        let mut found: Vec<(f64, Vec<f64>)> = Vec::with_capacity(8);
        let mut raw = Vec::with_capacity(8);
        // At the wrist singularity the seed's wrist pitch first; if no solution keeps to the
        // limits with it, pitches every 10 degrees.
        for pitch_samples in [0, 35] {
            raw.clear();
            let singular = match chain.kind {
                ClosedForm::Irp6 => irp6::solve(&irp6::IRP6_LENGTHS, &flange, &arm_seed, pitch_samples, &mut raw),
            };
            self.keep_solutions(chain, effector, target, seed, &limits, &raw, &mut found);
            if !singular || !found.is_empty() {
                break;
            }
        }
        found.sort_by(|a, b| a.0.total_cmp(&b.0));
        Ok(found.into_iter().map(|(_, q)| q).collect())
    }

    /// Turn raw closed-form angles into configurations within the limits that reach `target`,
    /// each with its distance from `seed`, skipping repeats.
    #[allow(clippy::too_many_arguments)]
    fn keep_solutions(
        &self,
        chain: &ArmChain,
        effector: &crate::robot::EndEffector,
        target: &Isometry3<f64>,
        seed: &[f64],
        limits: &[JointLimits],
        raw: &[[f64; 6]],
        found: &mut Vec<(f64, Vec<f64>)>,
    ) {
        let space = self.config_space();
        let moving = self.dofs_moving(effector.link);
        let screws = self.actuators_driving(|i| moving[i]);
        'solutions: for angles in raw {
            let mut q = seed.to_vec();
            for (k, &d) in chain.dofs.iter().enumerate() {
                let value = if self.dof_joint(d).kind == JointKind::Continuous {
                    angles[k] + TAU * ((seed[d] - angles[k]) / TAU).round()
                } else {
                    match turn_into(angles[k], &limits[d], seed[d]) {
                        Some(v) => v,
                        None => continue 'solutions,
                    }
                };
                q[d] = value;
            }
            // Only the chain to the flange: the check needs no other link (the other arm, say).
            let e = pose_error(&(self.link_pose(&q, effector.link) * effector.tool), target);
            let close =
                e.fixed_rows::<3>(0).norm() <= CLOSED_FORM_CHECK && e.fixed_rows::<3>(3).norm() <= CLOSED_FORM_CHECK;
            // Within the strokes of the screws that drive the arm too (a serial-parallel arm's
            // joint ranges are cut by them; the other screws' strokes are the seed's).
            let stroked = screws.iter().all(|a| a.stroke_excess(&q) <= 1e-9);
            if close && stroked && found.iter().all(|(_, o)| space.distance(o, &q) > 1e-9) {
                found.push((space.distance(seed, &q), q));
            }
        }
    }

    fn end_effector_checked(&self, ee: usize) -> Result<&crate::robot::EndEffector, ModelError> {
        self.end_effectors().get(ee).ok_or_else(|| ModelError::NoSuchName {
            robot: self.name().to_string(),
            what: "end effector",
            name: ee.to_string(),
        })
    }

    /// Joint values placing end effector `ee`'s tool frame at `target`, within the position limits
    /// (and the strokes of screws driving joints, [`Robot::actuators`]).
    ///
    /// Where the end effector has a closed form that covers every joint moving it (the IRp-6 on
    /// its postument), the answer is the closed-form solution nearest `seed`. Otherwise (and for
    /// `position_only`, or when no closed-form solution lies within the limits): damped least
    /// squares (Levenberg-Marquardt style), clamping every step into the limits and solving it
    /// along the joint limits and the ends of screw strokes it meets (so that it slides along
    /// them), with deterministic random restarts; a restart draws only the joints that move the end
    /// effector, so every other joint is returned as `seed` has it. Continuous joints are returned
    /// wrapped near the seed.
    pub fn inverse_kinematics(
        &self,
        ee: usize,
        target: &Isometry3<f64>,
        seed: &[f64],
        options: &IkOptions,
    ) -> Result<Vec<f64>, ModelError> {
        let effector = self.end_effector_checked(ee)?;
        self.check_joint_configuration(seed)?;
        let whole = self.closed_forms.get(ee).and_then(|c| c.as_ref()).is_some_and(|c| c.whole);
        if whole
            && options.closed_form
            && !options.position_only
            && let Some(q) = self.inverse_kinematics_all(ee, target, seed)?.into_iter().next()
        {
            let e = pose_error(&(self.link_pose(&q, effector.link) * effector.tool), target);
            let within = e.fixed_rows::<3>(0).norm() <= options.position_tolerance
                && e.fixed_rows::<3>(3).norm() <= options.orientation_tolerance;
            if within {
                return Ok(q);
            }
        }
        let limits = self.limits();
        let mut rng = Rng::new(options.seed);
        let mut best = (f64::INFINITY, seed.to_vec());
        let rot_weight = if options.position_only { 0.0 } else { 1.0 };
        let mut poses = self.forward_kinematics(seed);
        // Only the chain to the flange moves it (on two-irp6, not the other arm): the residual
        // and the Jacobian read no other pose.
        let chain = self.chain_to(effector.link);
        let moving = self.dofs_moving(effector.link);
        // The screws that drive those: the others' strokes are the caller's (the other arm's,
        // kept as the seed has it, in stroke or not).
        let screws = self.actuators_driving(|i| moving[i]);
        let residual_of = |poses: &mut Vec<Isometry3<f64>>, q: &[f64]| -> (Vector6<f64>, f64, f64) {
            self.chain_kinematics_into(&chain, q, poses);
            let e = pose_error(&(poses[effector.link] * effector.tool), target);
            let pos = e.fixed_rows::<3>(0).norm();
            let rot = if options.position_only { 0.0 } else { e.fixed_rows::<3>(3).norm() };
            (e, pos, rot)
        };
        // Rows of the error the solve uses: a position-only solve drops the rotation rows,
        // which leaves J J^T block diagonal with an identity block and those rows of y at zero.
        let mask = Vector6::new(1.0, 1.0, 1.0, rot_weight, rot_weight, rot_weight);
        let n = self.dof();
        let mut trial = seed.to_vec();
        let mut dq = vec![0.0; n];
        let mut frozen = vec![false; n];
        let mut active = vec![false; screws.len()];
        // The Jacobian projected off the drive angles of the screws at a stroke end.
        let mut projected = Matrix6xX::zeros(n);
        for attempt in 0..=options.restarts {
            // A restart draws only the joints that move the end effector: the others keep the
            // seed's values (the other arm of a two-arm robot stays where the caller has it).
            let mut q = seed.to_vec();
            if attempt > 0 {
                self.randomise_dofs_into(&mut rng, |i| moving[i], &mut q);
            }
            // Levenberg-Marquardt: accept a step only if it lowers the error, adapt the damping.
            let mut lambda = options.damping.max(1e-9);
            let (mut e, mut pos_err, mut rot_err) = residual_of(&mut poses, &q);
            let mut cost = pos_err * pos_err + rot_err * rot_err;
            // The Jacobian at q: recomputed only when a step is accepted (a rejected step leaves
            // q, and so the Jacobian, as it was; the poses then are the trial's).
            let mut jac = self.jacobian_with_poses(&poses, effector.link, &effector.tool);
            for _ in 0..options.max_iterations {
                if pos_err + rot_err < best.0 {
                    best = (pos_err + rot_err, q.clone());
                }
                let stroked = screws.iter().all(|a| a.stroke_excess(&q) <= 1e-9);
                if pos_err <= options.position_tolerance && rot_err <= options.orientation_tolerance && stroked {
                    return Ok(q);
                }
                // Active set: a joint at a bound that the step would push further out is frozen
                // (its column removed) and the step solved again, so bounds do not stall progress.
                // Likewise a screw at an end of its stroke: the step is solved in the joint
                // directions that keep its drive angle (the Jacobian times the projector
                // `I - w wᵀ / wᵀw`, `w` the angle's weights), so that it slides along that end.
                let err = e.component_mul(&mask);
                frozen.fill(false);
                active.fill(false);
                let mut solved = false;
                for _ in 0..3 {
                    let jp = if active.contains(&true) {
                        projected.copy_from(&jac);
                        for (a, _) in screws.iter().zip(&active).filter(|(_, on)| **on) {
                            let angle = || a.angle.iter().filter(|&&(k, _)| k < n);
                            let ww: f64 = angle().map(|&(_, w)| w * w).sum();
                            if ww > 0.0 {
                                let mut jw = Vector6::zeros();
                                for &(k, w) in angle() {
                                    jw += projected.column(k) * w;
                                }
                                for &(k, w) in angle() {
                                    let col = projected.column(k) - jw * (w / ww);
                                    projected.set_column(k, &col);
                                }
                            }
                        }
                        &projected
                    } else {
                        &jac
                    };
                    let mut jjt = Matrix6::identity() * lambda + Matrix6::from_diagonal(&mask.map(|m| 1.0 - m));
                    for c in (0..n).filter(|&c| !frozen[c]) {
                        let col = jp.column(c).component_mul(&mask);
                        jjt += col * col.transpose();
                    }
                    let Some(chol) = jjt.cholesky() else { break };
                    let y = chol.solve(&err);
                    for (c, v) in dq.iter_mut().enumerate() {
                        *v = if frozen[c] { 0.0 } else { jp.column(c).component_mul(&mask).dot(&y) };
                    }
                    solved = true;
                    let mut changed = false;
                    for i in 0..n {
                        let at_lower = q[i] <= limits[i].lower + 1e-12 && dq[i] < 0.0;
                        let at_upper = q[i] >= limits[i].upper - 1e-12 && dq[i] > 0.0;
                        if !frozen[i] && (at_lower || at_upper) {
                            frozen[i] = true;
                            changed = true;
                        }
                    }
                    for (a, on) in screws.iter().zip(active.iter_mut()) {
                        let rate = a.rate_along(&q, &dq);
                        let l = a.length(&q);
                        let pushing = (l >= a.max_length - STROKE_END && rate > 0.0)
                            || (l <= a.min_length + STROKE_END && rate < 0.0);
                        if !*on && pushing {
                            *on = true;
                            changed = true;
                        }
                    }
                    if !changed {
                        break;
                    }
                }
                if !solved {
                    lambda *= 10.0;
                    continue;
                }
                // Limit the step so that the linearisation stays valid.
                let largest = dq.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let scale = (0.5 / largest.max(1e-12)).min(1.0);
                for i in 0..n {
                    trial[i] = limits[i].clamp(q[i] + scale * dq[i]);
                }
                let (mut e2, mut p2, mut r2) = residual_of(&mut poses, &trial);
                let mut cost2 = p2 * p2 + r2 * r2;
                // A step out of a screw's stroke is refused like one that does not help; but
                // first it is tried again with its share across each screw it leaves cut to end
                // on that stroke's end: a solution there is reached by sliding along it, which
                // full steps, all pointing out, never do.
                let mut stroked = screws.iter().all(|a| a.stroke_excess(&trial) <= 1e-9);
                if !stroked && onto_strokes(&screws, &q, &trial, scale, &mut dq) {
                    for i in 0..n {
                        trial[i] = limits[i].clamp(q[i] + scale * dq[i]);
                    }
                    (e2, p2, r2) = residual_of(&mut poses, &trial);
                    cost2 = p2 * p2 + r2 * r2;
                    stroked = screws.iter().all(|a| a.stroke_excess(&trial) <= 1e-9);
                }
                if cost2 < cost && stroked {
                    q.copy_from_slice(&trial);
                    (e, pos_err, rot_err, cost) = (e2, p2, r2, cost2);
                    lambda = (lambda / 3.0).max(1e-12);
                    jac = self.jacobian_with_poses(&poses, effector.link, &effector.tool);
                } else {
                    lambda *= 4.0;
                    if lambda > 1e6 {
                        break; // stuck (a limit or a local minimum): restart elsewhere
                    }
                }
            }
        }
        Err(ModelError::IkFailed {
            frame: effector.name.clone(),
            residual: best.0,
            iterations: options.max_iterations * (options.restarts + 1),
        })
    }
}

/// How near an end of its stroke a screw counts as at it in the IK step, m.
const STROKE_END: f64 = 1e-6;

/// Change the step `q + scale dq` so that every screw that `trial` (the step as it was) takes out
/// of its stroke ends it at the end of its stroke instead: the component of `dq` along the
/// screw's drive-angle weights `w` is set so that the drive angle moves just short of the angle
/// where the screw has that length (`dq += ((t / scale) - w.dq) / (w.w) w`), or not at all when
/// no angle gives it. `false` when no screw was changed or nothing of the step remains.
fn onto_strokes(
    actuators: &[&crate::actuator::ScrewTriangle],
    q: &[f64],
    trial: &[f64],
    scale: f64,
    dq: &mut [f64],
) -> bool {
    let mut any = false;
    for a in actuators.iter().filter(|a| a.stroke_excess(trial) > 1e-9) {
        let (mut wd, mut ww) = (0.0, 0.0);
        for &(k, w) in &a.angle {
            wd += w * dq.get(k).copied().unwrap_or(0.0);
            ww += w * w;
        }
        if !(ww > 0.0 && scale > 0.0) {
            continue;
        }
        let theta = a.theta(q);
        let bound = if a.length_at(a.theta(trial)) > a.max_length { a.max_length } else { a.min_length };
        let end = a.theta_for_length(bound, theta).map_or(0.0, |t| t - theta);
        // Just short of the end (and never past the step's own direction).
        let t = if end * wd > 0.0 { end * (1.0 - 1e-6) } else { 0.0 };
        for &(k, w) in &a.angle {
            if let Some(v) = dq.get_mut(k) {
                *v += (t / scale - wd) / ww * w;
            }
        }
        any = true;
    }
    any && dq.iter().any(|v| v.abs() > 1e-15)
}
