//! The controlled stop along the path ([`PathHalt`]): over random paths (planned trajectories
//! of a built-in arm and curved analytic paths) and random halt instants, the effector follows
//! the path exactly, and the halt stays on the path to 1e-9, within every joint's velocity,
//! acceleration and position limits, and comes to rest.

use embodied_executor::{
    CommandMode, Effector, FollowedPath, JointCommand, PathHalt, SafetyLimiter, ServoModel, StopMotion, predict_stop,
};
use embodied_models::JointLimits;
use embodied_planner::trajectory::{Trajectory, time_parameterize};
use proptest::prelude::*;

const DT: f64 = 0.001;
const ON_PATH: f64 = 1e-9;

/// A curved path: `q_j(s) = c_j + a_j (1 - cos(w_j s))`, at rest at `s = 0`, its speed and
/// acceleration at rate 1 within 90% of the limits.
struct Curve {
    c: Vec<f64>,
    a: Vec<f64>,
    w: Vec<f64>,
    end: f64,
}

impl FollowedPath for Curve {
    fn end(&self) -> f64 {
        self.end
    }
    fn position_into(&self, s: f64, out: &mut [f64]) {
        let s = s.clamp(0.0, self.end);
        for (j, o) in out.iter_mut().enumerate() {
            *o = self.c[j] + self.a[j] * (1.0 - (self.w[j] * s).cos());
        }
    }
}

fn point<P: FollowedPath + ?Sized>(path: &P, s: f64, dof: usize) -> Vec<f64> {
    let mut q = vec![0.0; dof];
    path.position_into(s, &mut q);
    q
}

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()))
}

/// Follow `path` at its own pace for `follow` steps (the consistent one-step command with the
/// chord velocity), then halt along it; check every step. Returns the halt's steps.
fn follow_then_halt<P: FollowedPath + ?Sized>(
    path: &P,
    limits: &[JointLimits],
    follow: usize,
) -> Result<usize, TestCaseError> {
    let dof = limits.len();
    let start = point(path, 0.0, dof);
    let mut servo = SafetyLimiter::new(ServoModel::new(limits.to_vec(), &start).expect("valid limits"));
    let mut cmd = JointCommand::hold(&start);
    let mut prev_v = vec![0.0; dof];
    let check = |servo: &SafetyLimiter<ServoModel>, prev_v: &mut Vec<f64>| -> Result<(), TestCaseError> {
        for (j, l) in limits.iter().enumerate() {
            let (q, v) = (servo.q()[j], servo.qd()[j]);
            prop_assert!(q >= l.lower && q <= l.upper, "joint {j} at {q} outside [{}, {}]", l.lower, l.upper);
            prop_assert!(v.abs() <= l.max_velocity * (1.0 + 1e-9), "joint {j} speed {v} over {}", l.max_velocity);
            let acc = (v - prev_v[j]) / DT;
            prop_assert!(
                acc.abs() <= l.max_acceleration * (1.0 + 1e-6),
                "joint {j} acceleration {acc} over {}",
                l.max_acceleration
            );
            prev_v[j] = v;
        }
        Ok(())
    };
    let mut s = 0.0;
    for k in 1..=follow {
        let next = point(path, k as f64 * DT, dof);
        cmd.mode = CommandMode::Position;
        let prev = point(path, (k - 1) as f64 * DT, dof);
        for (j, (&n, &p)) in next.iter().zip(&prev).enumerate() {
            cmd.qd[j] = (n - p) / DT;
            cmd.q[j] = n;
        }
        servo.execute(&cmd, DT);
        check(&servo, &mut prev_v)?;
        s = k as f64 * DT;
        // A trajectory's timing at a limit rounds a hair over it at places; the limiter clips
        // it, a few 1e-10 off.
        let off = distance(servo.q(), &point(path, s, dof));
        prop_assert!(off <= 1e-8, "following: {off} off the path at s = {s}");
    }
    let mut halt = PathHalt::new(s, 1.0);
    let predicted = predict_stop(StopMotion::Path, Some((path, &halt)), servo.q(), servo.qd(), limits, DT, 100_000);
    let mut steps = 0;
    loop {
        let on = halt.command_into(path, servo.q(), servo.qd(), limits, DT, &mut cmd);
        prop_assert!(on, "no step along the path fits the limits at s = {} (end {})", halt.s(), path.end());
        servo.execute(&cmd, DT);
        check(&servo, &mut prev_v)?;
        steps += 1;
        // On the path from the first halting step on, whatever the following left.
        let off = distance(servo.q(), &point(path, halt.s(), dof));
        prop_assert!(off <= ON_PATH, "halting: {off} off the path at s = {}", halt.s());
        // The prediction checked for collision is the motion executed.
        if let Some(p) = predicted.get(steps) {
            let d = distance(servo.q(), p);
            prop_assert!(d <= ON_PATH, "step {steps}: {d} from the predicted stop");
        }
        if servo.qd().iter().all(|v| v.abs() < 1e-9) {
            break;
        }
        prop_assert!(steps < 100_000, "no rest after {steps} steps");
    }
    prop_assert_eq!(predicted.len(), steps + 1, "the predicted stop has another length");
    Ok(steps)
}

/// The stopping time bound: the slowest joint's `|v| / a` stretched by the path's turns; the
/// halt must not take more than a few times the straight-line stop.
fn straight_stop_steps(qd: &[f64], limits: &[JointLimits]) -> f64 {
    qd.iter().zip(limits).map(|(v, l)| v.abs() / l.max_acceleration).fold(0.0, f64::max) / DT
}

fn rnt() -> embodied_models::Robot {
    embodied_models::builtin("rnt").expect("built-in robot")
}

/// The built-in RNT's trajectory through `fractions` of each joint's range (knots only, as the
/// motion planner delivers plans), and its joint limits.
fn rnt_plan(fractions: &[Vec<f64>]) -> (Trajectory, Vec<JointLimits>) {
    let robot = rnt();
    let limits = robot.limits();
    let waypoints: Vec<Vec<f64>> = fractions
        .iter()
        .map(|f| f.iter().zip(&limits).map(|(x, l)| l.lower + x * (l.upper - l.lower)).collect())
        .collect();
    (time_parameterize(&waypoints, &robot, 0.0), limits)
}

/// Follow [`rnt_plan`] to `at` of its duration, then halt along it.
fn halt_on_the_rnt_plan(fractions: &[Vec<f64>], at: f64) -> Result<usize, TestCaseError> {
    let (traj, limits) = rnt_plan(fractions);
    let follow = (at * traj.duration() / DT) as usize;
    follow_then_halt(&traj, &limits, follow)
}

/// Follow [`rnt_plan`] for `follow` steps, then halt along it.
fn halt_on_the_rnt_plan_after(fractions: &[Vec<f64>], follow: usize) -> Result<usize, TestCaseError> {
    let (traj, limits) = rnt_plan(fractions);
    follow_then_halt(&traj, &limits, follow)
}

/// A halt begun 0.14 s before the end of a segment that brakes joint 0 at its limit: the
/// follower's last step leaves the arm 1e-10 off the path, so the halt runs a hair faster than
/// the path's own pace, and a braking path at rate `r > 1` needs ever larger rates towards its
/// end (1.0015 one step before it). No rate near the current one fits there; the path's end
/// does, and the halt must find the smallest rate up to it.
#[test]
fn halt_near_the_end_of_a_braking_segment_reaches_the_end_on_the_path() {
    let fractions = vec![
        vec![0.05; 6],
        vec![0.6958398090207563, 0.7464302146540732, 0.9412782624526715, 0.05, 0.05, 0.05],
        vec![0.9467381720280804, 0.8095275116190801, 0.5216982064676357, 0.05, 0.05, 0.05],
        vec![0.12292489986376282, 0.05, 0.05, 0.05, 0.05, 0.05],
    ];
    let steps = halt_on_the_rnt_plan(&fractions, 0.9935613664323945).expect("the halt stays on the path");
    // The segment's own stop takes 144 steps; the halt may not take more than a few beyond it.
    assert!((140..=150).contains(&steps), "{steps} steps to stop");
}

/// A halt begun 1.27 ms before a rest point of the path (waypoint 3, at 18.07427 s), where
/// joint 0 brakes at its limit: the follower left it 6.5e-9 rad ahead of the path and a hair
/// fast, so a step at the path's own pace brakes harder than its limit allows, and only a
/// faster one (rates 1.1 to 1.8, reaching the rest point sooner) fits.
#[test]
fn halt_just_ahead_of_a_rest_point_finds_a_faster_step_on_the_path() {
    let fractions = vec![
        vec![
            0.2404873448472124,
            0.24756133781601697,
            0.14108636292195031,
            0.42559911718354226,
            0.6323721820916482,
            0.6612220222191326,
        ],
        vec![
            0.8828734439716114,
            0.383451448972118,
            0.6720921503740726,
            0.5435189553495524,
            0.22979469766862598,
            0.5455664969494566,
        ],
        vec![
            0.6113248813771494,
            0.1406528728485264,
            0.24327727909709235,
            0.9499537192338191,
            0.6657604334522046,
            0.5671368102753707,
        ],
        vec![
            0.14663795319188033,
            0.1278926106381949,
            0.8141885225469784,
            0.40430941450572894,
            0.46581122453934265,
            0.12929988395435774,
        ],
        vec![
            0.37001540361893714,
            0.2222082474159377,
            0.17366899388230617,
            0.804995070369118,
            0.1853040785277762,
            0.8365782010388918,
        ],
    ];
    let steps = halt_on_the_rnt_plan_after(&fractions, 18_073).expect("the halt stays on the path");
    // It stops at the rest point, 1.27 ms on.
    assert!((2..=4).contains(&steps), "{steps} steps to stop");
}

/// A halt begun 0.99 ms before a rest point of the path (waypoint 2, at 10.118994 s) that falls
/// between two control steps: joint 0, braking at its limit, can stop there only by braking
/// 1.8e-7 rad/s harder than its window allows, and the path turns back beyond it, so no step
/// along the path fits. The step that leaves the windows least overshoots the rest point by
/// about 2e-10 rad; the limiter clamps it and the halt goes on along the path.
#[test]
fn halt_at_a_rest_point_between_two_steps_stays_within_a_hair_of_the_path() {
    let fractions = vec![
        vec![
            0.09879427978446371,
            0.47129435000963066,
            0.5525882118533709,
            0.837757492358771,
            0.6526821213244488,
            0.8631178715522773,
        ],
        vec![
            0.4706624776609378,
            0.5069973139779048,
            0.0808183200302009,
            0.47032643447886224,
            0.5354701481952567,
            0.7801090359131163,
        ],
        vec![
            0.8642494678126619,
            0.8780675046467484,
            0.7216257905760672,
            0.15379125886340161,
            0.46867387522105763,
            0.7183235795517346,
        ],
        vec![
            0.7081108702058331,
            0.16362078449549772,
            0.4851340161501141,
            0.5592889740542857,
            0.5939174527924926,
            0.5821563964527552,
        ],
        vec![
            0.7024359045281402,
            0.12121521484052279,
            0.8190684640437105,
            0.07702320643190415,
            0.11857814596360573,
            0.203136409979362,
        ],
    ];
    for follow in [10_116, 10_117, 10_118] {
        halt_on_the_rnt_plan_after(&fractions, follow).expect("the halt stays on the path");
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn halt_on_a_planned_trajectory_stays_on_it(
        fractions in prop::collection::vec(prop::collection::vec(0.05f64..0.95, 6), 2..5),
        at in 0.0f64..1.0,
    ) {
        halt_on_the_rnt_plan(&fractions, at)?;
    }

    #[test]
    fn halt_on_a_curved_path_stays_on_it(
        joints in prop::collection::vec((0.3f64..3.0, 1.0f64..20.0, 0.5f64..6.0, -1.0f64..1.0), 1..8),
        at in 0.0f64..3.0,
    ) {
        let limits: Vec<JointLimits> = joints
            .iter()
            .map(|&(v, a, _, _)| JointLimits::new(-100.0, 100.0, v, a))
            .collect();
        let w: Vec<f64> = joints.iter().map(|j| j.2).collect();
        let a: Vec<f64> = joints
            .iter()
            .map(|&(v, acc, w, _)| (0.9 * v / w).min(0.9 * acc / (w * w)))
            .collect();
        let c: Vec<f64> = joints.iter().map(|j| j.3).collect();
        let curve = Curve { c, a, w, end: 100.0 };
        let follow = (at / DT) as usize;
        let steps = follow_then_halt(&curve, &limits, follow)?;
        // From full speed along the curve the stop is not much longer than a straight one.
        let s = follow as f64 * DT;
        let v: Vec<f64> = (0..limits.len())
            .map(|j| curve.a[j] * curve.w[j] * (curve.w[j] * s).sin())
            .collect();
        let bound = straight_stop_steps(&v, &limits);
        prop_assert!(steps as f64 <= 3.0 * bound + 10.0, "{steps} steps to stop, straight bound {bound:.0}");
    }
}
