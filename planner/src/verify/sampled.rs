//! The sampled collision check: every sample with `first_collision` (to name the pair), every
//! sample-to-sample segment with the model's own `motion_is_free` at the caller's resolution,
//! then walked in order to say where. A thin obstacle between two checked points can be missed:
//! this is the classic discrete check, cheaper than the certificate and weaker.

use std::time::Instant;

use embodied_models::collision::CollisionModel;

use super::certified::segment_models;
use super::finding::Finding;
use super::report::CollisionReport;
use crate::carry::ClosedChainSpan;
use crate::trajectory::Trajectory;

/// A configuration in collision, as a finding (the pair from `first_collision`, the depth
/// from the model's signed distance). `None` when `q` is free.
fn collision_at(model: &CollisionModel, t: f64, q: &[f64]) -> Option<Finding> {
    let contact = model.first_collision(q)?;
    let penetration_m = (-model.distance(q).distance).max(0.0);
    Some(Finding::Collision { t, q: q.to_vec(), a: contact.a.to_string(), b: contact.b.to_string(), penetration_m })
}

/// Check the samples of `traj` and the straight segments between them (the short way round on
/// continuous joints) at `resolution` (largest joint step between checked points). Inside a
/// closed-chain span with an object, the object is attached.
pub(crate) fn sample_collisions(
    model: &CollisionModel,
    traj: &Trajectory,
    spans: &[ClosedChainSpan],
    resolution: f64,
) -> CollisionReport {
    let start = Instant::now();
    let n = traj.q.len();
    let obstacles = model.environment().obstacles().len();
    let shaped = model.robot().links().iter().filter(|l| !l.shapes.is_empty()).count();
    let mut report = CollisionReport {
        ok: true,
        violation: None,
        segments: n.saturating_sub(1),
        certified_segments: 0,
        distance_evaluations: 0,
        subdivisions: 0,
        max_depth: 0,
        pairs: shaped * obstacles + model.self_collision_pairs().len(),
        min_clearance_m: f64::NAN,
        certified_clearance_m: f64::NAN,
        closest_pair: None,
        time_s: 0.0,
    };
    let result = if !(resolution.is_finite() && resolution > 0.0) {
        Err(Finding::Malformed {
            message: format!("the sampling resolution must be positive and finite, got {resolution}"),
        })
    } else {
        match segment_models(model, traj, spans) {
            Ok((models, which)) => walk(model, &models, &which, traj, resolution, &mut report),
            Err(message) => Err(Finding::Malformed { message }),
        }
    };
    if let Err(f) = result {
        report.ok = false;
        report.violation = Some(f);
    }
    report.time_s = start.elapsed().as_secs_f64();
    report
}

// A finding is returned once, when the check refuses: boxing it would only burden callers'
// pattern matching.
#[allow(clippy::result_large_err)]
fn walk(
    plain: &CollisionModel,
    models: &[CollisionModel],
    which: &[usize],
    traj: &Trajectory,
    resolution: f64,
    report: &mut CollisionReport,
) -> Result<(), Finding> {
    let (t, q) = (&traj.t, &traj.q);
    let space = plain.robot().config_space();
    let model_of = |k: usize| which.get(k).and_then(|&id| models.get(id)).unwrap_or(plain);
    for k in 0..q.len() {
        // A sample is checked with the model of the segment it starts (the last: it ends).
        let m = model_of(k.min(q.len().saturating_sub(2)));
        if let Some(f) = collision_at(m, t[k], &q[k]) {
            return Err(f);
        }
    }
    for k in 0..q.len().saturating_sub(1) {
        let m = model_of(k);
        let (a, b) = (&q[k], &q[k + 1]);
        if m.motion_is_free(a, b, resolution) {
            report.certified_segments += 1;
            continue;
        }
        // Find the first colliding point in order, to say where.
        let steps = (space.max_joint_step(a, b) / resolution).ceil().clamp(1.0, 1e7) as usize;
        for s in 0..=steps {
            let fraction = s as f64 / steps as f64;
            let at = t[k] + fraction * (t[k + 1] - t[k]);
            if let Some(f) = collision_at(m, at, &space.interpolate(a, b, fraction)) {
                return Err(f);
            }
        }
        let (ta, tb) = (t[k], t[k + 1]);
        return Err(Finding::NotCertified {
            t_from: ta,
            t_to: tb,
            q_from: a.clone(),
            q_to: b.clone(),
            a: String::new(),
            b: String::new(),
            clearance_m: f64::NAN,
            reason: format!("motion_is_free at resolution {resolution} refuses the segment, no sample collides"),
        });
    }
    Ok(())
}
