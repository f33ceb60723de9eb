//! RNT polishing under a regulated contact force (`rnt-polish-raster`): the coverage path covers
//! the plate, the force stays in its band, every joint and screw limit holds, and the log
//! verifies; all of it read back from the run log and recomputed from the logged joints.
#![allow(clippy::unwrap_used)]

mod common;
use common::tmp;

use embodied_executor::Event;
use embodied_planner::verify::CheckSettings;
use embodied_system::polish::{PolishJob, contact_of, coverage};
use embodied_system::scenario::load_scenario;
use embodied_system::system::{RunArgs, run_scenario};
use embodied_system::verify::verify_log;

#[test]
fn the_raster_covers_the_plate_at_the_regulated_force_within_every_limit_and_the_log_verifies() {
    let scenario = load_scenario("rnt-polish-raster").unwrap();
    let spec = scenario.polish.clone().unwrap();
    let job = PolishJob::plan(&scenario, &spec).unwrap();
    let robot = &scenario.agents[spec.agent].robot;
    let limit = scenario.agents[spec.agent].behaviour.force_limit.unwrap();
    // The plan: passes along the plate's 1 m side, at most 1.8 pad radii apart, whose swept
    // band covers the face.
    assert!(job.passes.len() >= 5, "{}", job.passes.len());
    // (The planned tool points ride at the pad's free thickness above the face: zero force.)
    let planned: Vec<[f64; 2]> = job
        .raster
        .q
        .iter()
        .map(|q| robot.end_effector_poses(q, 0).1.translation.vector)
        .inspect(|p| assert!((p.z - job.top_z - spec.skin).abs() < 1e-6, "{p:?}"))
        .map(|p| [p.x, p.y])
        .collect();
    let planned_coverage = coverage(job.face, &planned, spec.tool_radius, 0.005);
    assert!(planned_coverage >= 0.99, "{planned_coverage} from {} points, face {:?}", planned.len(), job.face);

    let path = tmp("rnt-polish-raster.jsonl");
    let args = RunArgs { scenario: "rnt-polish-raster".into(), log: Some(path.to_path_buf()), ..RunArgs::default() };
    let (summary, _) = run_scenario(&args).unwrap();
    assert!(summary.failure.is_none(), "{:?}", summary.failure);
    let text = std::fs::read_to_string(&*path).unwrap();
    let steps: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .filter(|l: &serde_json::Value| l.get("step").is_some())
        .collect();
    let floats =
        |v: &serde_json::Value| -> Vec<f64> { v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect() };

    // Typed events, in order: contact, regulated, one per pass, done; never the stop.
    let events: Vec<Event> = steps
        .iter()
        .flat_map(|s| s["agents"]["rnt"]["events"].as_array().unwrap().clone())
        .map(|e| serde_json::from_value(e).unwrap())
        .collect();
    let kinds: Vec<&str> = events.iter().map(|e| e.kind()).collect();
    let passes = job.passes.len();
    let mut expected = vec!["contact_made", "force_regulated"];
    expected.extend(std::iter::repeat_n("pass_finished", passes));
    expected.push("goal_reached");
    assert_eq!(kinds, expected, "{events:?}");
    for e in &events {
        if let Event::PassFinished { mean_force_n, .. } = e {
            assert!((mean_force_n - spec.force_n).abs() < spec.band_n, "{e}");
        }
    }

    // From the logged joints alone: where the pad touched the plate, and with what force
    // (the world's spring contact, without the sensor's noise).
    let (mut touched, mut in_band, mut contact_steps, mut peak) = (Vec::new(), 0usize, 0usize, 0.0_f64);
    let (mut speed_ratio, mut strokes_ok) = (0.0_f64, true);
    for s in &steps {
        let (q, qd) = (floats(&s["agents"]["rnt"]["q"]), floats(&s["agents"]["rnt"]["qd"]));
        speed_ratio = speed_ratio.max(robot.actuator_speed_ratio(&q, &qd));
        strokes_ok &= robot.within_limits(&q);
        if let Some((p, force)) = contact_of(robot, &job, &q) {
            touched.push(p);
            contact_steps += 1;
            peak = peak.max(force);
            if (force - spec.force_n).abs() <= spec.band_n {
                in_band += 1;
            }
        }
    }
    let covered = coverage(job.face, &touched, spec.tool_radius, 0.005);
    let share = in_band as f64 / contact_steps as f64;
    eprintln!(
        "rnt-polish-raster: {passes} passes at {:.3} m/s planned in {:.0} ms; {contact_steps} contact steps, \
         {:.1}% in the band, peak {peak:.1} N; {:.1}% of the face covered; peak screw speed {:.3} of its limit",
        job.speed,
        job.planning_ms,
        100.0 * share,
        100.0 * covered,
        speed_ratio
    );
    assert!(covered >= 0.95, "covered {covered}");
    assert!(share >= 0.9, "in band {share}");
    assert!(peak < limit, "peak {peak} N");
    assert!(strokes_ok && speed_ratio <= 1.0 + 1e-6, "screw speed {speed_ratio}");

    let v = verify_log(&scenario, &path, &CheckSettings::default()).unwrap();
    assert!(v.certified && v.complete, "{v:?}");
}

/// The builder makes the same polishing scenario as the `[polish]` table, and refuses a job
/// the table would refuse, with the same words.
#[test]
fn the_builder_gives_the_polishing_scenario_of_the_table() {
    use embodied_models::collision::Obstacle;
    use embodied_models::nalgebra::Isometry3;
    use embodied_models::{Shape, builtin};
    use embodied_system::scenario::{AgentSpec, PolishSpec, Scenario};
    let table = load_scenario("rnt-polish-raster").unwrap();
    let plate = Obstacle::new("plate", Isometry3::translation(1.43, 0.0, 0.25), Shape::cuboid(0.3, 0.5, 0.25));
    let agent = || {
        AgentSpec::new("rnt", builtin("rnt").unwrap())
            .start(vec![-0.37, -1.19, -0.63, 0.0, 0.25, -0.37])
            .force_limit(60.0)
    };
    let job =
        PolishSpec { force_n: 20.0, band_n: 5.0, tool_radius: 0.06, speed: 0.2, skin: 0.005, ..PolishSpec::new(0, 0) };
    let built = Scenario::builder("rnt-polish-raster")
        .agent(agent())
        .obstacle(plate.clone())
        .polish(job.clone())
        .build()
        .unwrap();
    assert_eq!(built.polish, table.polish);
    assert_eq!(format!("{:?}", built.obstacles[0].obstacle.shape), format!("{:?}", table.obstacles[0].obstacle.shape));
    // The same job through both doors: a force band reaching the force limit is refused.
    let strong = PolishSpec { force_n: 58.0, ..job.clone() };
    let err =
        Scenario::builder("b").agent(agent()).obstacle(plate.clone()).polish(strong).build().unwrap_err().to_string();
    assert!(err.contains("polish: force_n + band_n (63 N) must stay below agent `rnt`'s force_limit (60 N)"), "{err}");
    let text = include_str!("../scenarios/rnt-polish-raster.toml").replace("force_n = 20.0", "force_n = 58.0");
    let err =
        Scenario::from_toml(&text, std::path::Path::new("p.toml"), std::path::Path::new(".")).unwrap_err().to_string();
    assert!(err.contains("polish: force_n + band_n (63 N) must stay below agent `rnt`'s force_limit (60 N)"), "{err}");
    // A workpiece index that names no obstacle, and a pad out of range.
    let err = Scenario::builder("b").agent(agent()).polish(job.clone()).build().unwrap_err().to_string();
    assert!(err.contains("polish: no obstacle #0"), "{err}");
    let wide = PolishSpec { tool_radius: 2.0, ..job };
    let err = Scenario::builder("b").agent(agent()).obstacle(plate).polish(wide).build().unwrap_err().to_string();
    assert!(err.contains("polish: tool_radius: expected 0.005..0.5 m, got 2"), "{err}");
}
