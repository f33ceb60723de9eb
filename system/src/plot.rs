//! `embodied run --plot`: an SVG of the run that people can read.
//!
//! One panel per agent and unit (joint angles in rad, track positions in m), each joint's limits
//! as dashed lines in its colour, the events (plan landed, halt, grasp, release, goal, failure)
//! as labelled vertical lines; for a two-handed carry, the closure error (drift of the two
//! tools' relative pose from its value at the grasp) while the object is held; and the
//! clearance over time. The legend sits beside each panel, never over the curves.

use std::path::Path;

use embodied_models::JointKind;
use embodied_planner::carry::{pose_difference, relative_tool_pose};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::SystemError as AppError;
use crate::scenario::Scenario;
use crate::view::{Track, build_scene};

/// One curve: its name and points.
type Series = (String, Vec<(f64, f64)>);

/// A panel: title, y-axis label, curves, and horizontal dashed lines (value, curve index).
struct Panel {
    title: String,
    y_label: String,
    series: Vec<Series>,
    limits: Vec<(f64, usize)>,
}

const PANEL_HEIGHT: u32 = 250;
const WIDTH: u32 = 1200;
const LEGEND_WIDTH: u32 = 220;

/// The panels of a run: per agent its joints by unit, then the carry's closure error and the
/// clearance.
fn panels(scenario: &Scenario, track: &Track) -> Result<Vec<Panel>, AppError> {
    let mut out = Vec::new();
    for (k, agent) in scenario.agents.iter().enumerate() {
        let robot = &agent.robot;
        let limits = robot.limits();
        let names = robot.joint_names();
        for (linear, unit) in [(false, "q [rad]"), (true, "q [m]")] {
            let joints: Vec<usize> =
                (0..robot.dof()).filter(|&j| (robot.dof_joint(j).kind == JointKind::Prismatic) == linear).collect();
            if joints.is_empty() {
                continue;
            }
            let mut panel = Panel {
                title: format!("{}: {}", agent.name, if linear { "linear joints" } else { "revolute joints" }),
                y_label: unit.to_string(),
                series: Vec::new(),
                limits: Vec::new(),
            };
            for (i, &j) in joints.iter().enumerate() {
                let points = track
                    .frames
                    .iter()
                    .filter_map(|f| f.q[k].as_ref().and_then(|q| q.get(j)).map(|v| (f.t, *v)))
                    .collect();
                panel.series.push((names[j].clone(), points));
                for v in [limits[j].lower, limits[j].upper] {
                    if v.is_finite() {
                        panel.limits.push((v, i));
                    }
                }
            }
            out.push(panel);
        }
    }
    if let Some(spec) = &scenario.carry {
        let agent = &scenario.agents[spec.agent];
        let held = |label: &str| track.events.iter().find(|e| e.agent == agent.name && e.kind == label).map(|e| e.t);
        if let Some(grasp) = held("grasp") {
            let release = held("release").unwrap_or(f64::INFINITY);
            let mut reference = None;
            let (mut metres, mut radians) = (Vec::new(), Vec::new());
            for f in track.frames.iter().filter(|f| f.t + 1e-9 >= grasp && f.t < release) {
                let Some(q) = f.q[spec.agent].as_ref().filter(|q| q.len() == agent.robot.dof()) else { continue };
                let relative = relative_tool_pose(&agent.robot, q, spec.end_effectors);
                let reference = *reference.get_or_insert(relative);
                let (m, rad) = pose_difference(&reference, &relative);
                metres.push((f.t, m * 1e6));
                radians.push((f.t, rad * 1e6));
            }
            out.push(Panel {
                title: format!("{}: closure error while holding `{}`", agent.name, spec.object),
                y_label: "µm | µrad".into(),
                series: vec![("position [µm]".into(), metres), ("rotation [µrad]".into(), radians)],
                limits: Vec::new(),
            });
        }
    }
    let scene = build_scene(scenario, track, &scenario.name, "plot")?;
    let clearance: Vec<(f64, f64)> =
        scene.times.iter().zip(&scene.clearance).filter_map(|(t, c)| c.as_ref().map(|c| (*t, c.m * 1e3))).collect();
    if !clearance.is_empty() {
        out.push(Panel {
            title: "clearance: nearest agent (with what it holds) to an obstacle or another agent".into(),
            y_label: "clearance [mm]".into(),
            series: vec![("clearance [mm]".into(), clearance)],
            limits: Vec::new(),
        });
    }
    Ok(out)
}

/// Write the run's plot: `track` holds its frames and events.
pub fn plot_run(path: &Path, scenario: &Scenario, track: &Track) -> Result<(), AppError> {
    let fail = |e: String| AppError::Failed(format!("plot {}: {e}", path.display()));
    let panels = panels(scenario, track)?;
    let t_end = track.frames.last().map_or(1.0, |f| f.t).max(1e-3);
    let height = PANEL_HEIGHT * panels.len().max(1) as u32 + 40;
    let root = SVGBackend::new(path, (WIDTH, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
    let (top, body) = root.split_vertically(40);
    top.draw(&Text::new(
        format!("{}: the run, {:.2} s", scenario.name, t_end),
        (10, 10),
        ("sans-serif", 20).into_font(),
    ))
    .map_err(|e| fail(e.to_string()))?;
    let events: Vec<(f64, String)> = track
        .events
        .iter()
        .filter(|e| e.kind != "other")
        .map(|e| (e.t, format!("{} {}", e.agent, short(&e.label))))
        .collect();
    let areas = body.split_evenly((panels.len().max(1), 1));
    for (panel, area) in panels.iter().zip(&areas) {
        draw_panel(panel, area, t_end, &events).map_err(fail)?;
    }
    root.present().map_err(|e| fail(e.to_string()))?;
    Ok(())
}

/// An event's label, cut at its first field.
fn short(label: &str) -> String {
    let head: String = label.split([' ', ':']).next().unwrap_or(label).chars().take(24).collect();
    head
}

fn draw_panel(
    panel: &Panel,
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    t_end: f64,
    events: &[(f64, String)],
) -> Result<(), String> {
    let (chart_area, legend) = area.split_horizontally(WIDTH - LEGEND_WIDTH);
    let (mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY);
    for (_, pts) in &panel.series {
        for &(_, y) in pts {
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    if !y0.is_finite() {
        (y0, y1) = (0.0, 1.0);
    }
    // Limits near the curves widen the plot to show them; limits far away (continuous-like
    // wrists of ±10 rad) would squash the curves and are only named in the legend.
    let reach = ((y1 - y0) * 0.6).max(0.3);
    let (shown, far): (Vec<(f64, usize)>, Vec<(f64, usize)>) =
        panel.limits.iter().partition(|(v, _)| *v >= y0 - reach && *v <= y1 + reach);
    for &(v, _) in &shown {
        y0 = y0.min(v);
        y1 = y1.max(v);
    }
    let pad = ((y1 - y0) * 0.08).max(1e-6);
    let (y0, y1) = (y0 - pad, y1 + pad * 2.5);
    let mut chart = ChartBuilder::on(&chart_area)
        .caption(&panel.title, ("sans-serif", 15))
        .margin(6)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..t_end, y0..y1)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc("t [s]")
        .y_desc(panel.y_label.as_str())
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(|e| e.to_string())?;
    let grey = RGBColor(110, 110, 110);
    for (t, label) in events {
        chart.draw_series(LineSeries::new([(*t, y0), (*t, y1)], grey.stroke_width(1))).map_err(|e| e.to_string())?;
        let style = ("sans-serif", 11)
            .into_font()
            .transform(FontTransform::Rotate90)
            .color(&grey)
            .pos(Pos::new(HPos::Left, VPos::Top));
        chart.draw_series([Text::new(label.clone(), (*t, y1), style)]).map_err(|e| e.to_string())?;
    }
    for &(v, i) in &shown {
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(DashedLineSeries::new([(0.0, v), (t_end, v)], 6, 4, color.mix(0.6).stroke_width(1)))
            .map_err(|e| e.to_string())?;
    }
    for (i, (_, pts)) in panel.series.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        chart.draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(2))).map_err(|e| e.to_string())?;
    }
    // The legend, beside the chart.
    for (i, (name, _)) in panel.series.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        let y = 30 + 16 * i as i32;
        legend.draw(&PathElement::new(vec![(6, y), (26, y)], color.stroke_width(2))).map_err(|e| e.to_string())?;
        legend
            .draw(&Text::new(name.clone(), (32, y - 6), ("sans-serif", 12).into_font()))
            .map_err(|e| e.to_string())?;
    }
    if !panel.limits.is_empty() {
        let mut y = 30 + 16 * panel.series.len() as i32 + 4;
        legend
            .draw(&Text::new("dashed: joint limits", (6, y), ("sans-serif", 11).into_font().color(&grey)))
            .map_err(|e| e.to_string())?;
        let mut far_names: Vec<&str> = far.iter().map(|(_, i)| panel.series[*i].0.as_str()).collect();
        far_names.dedup();
        for name in far_names {
            y += 14;
            let text = format!("{name}: limits off the plot");
            legend
                .draw(&Text::new(text, (6, y), ("sans-serif", 11).into_font().color(&grey)))
                .map_err(|e| e.to_string())?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn the_carry_plot_has_a_panel_per_unit_the_closure_and_the_clearance() {
        let sc = crate::scenario::load_scenario("two-irp6-carry").unwrap();
        let plan = crate::plan::plan_scenario(&sc, None).unwrap();
        let track = crate::view::track_from_plan(&sc, &plan).unwrap();
        let titles: Vec<String> = panels(&sc, &track).unwrap().iter().map(|p| p.title.clone()).collect();
        assert_eq!(
            titles,
            [
                "pair: revolute joints",
                "pair: linear joints",
                "pair: closure error while holding `bar`",
                "clearance: nearest agent (with what it holds) to an obstacle or another agent"
            ]
        );
        let dir = std::env::temp_dir().join(format!("embodied-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("carry.svg");
        plot_run(&path, &sc, &track).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        for text in
            ["q [rad]", "q [m]", "ot_track", "pair grasp", "pair release", "dashed: joint limits", "clearance [mm]"]
        {
            assert!(svg.contains(text), "the plot lacks `{text}`");
        }
    }
}
