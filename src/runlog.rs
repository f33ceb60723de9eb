//! The run log: JSON Lines, one header line, one line per control step, one summary line.
//!
//! Every line is written and flushed as soon as it exists, so a run that fails or is
//! interrupted leaves a valid log up to its last step.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::AppError;

/// Where log lines go.
pub struct RunLog {
    out: Option<(PathBuf, BufWriter<File>)>,
    lines: usize,
}

impl RunLog {
    /// A log written to `path`, or a log that discards lines when `path` is `None`.
    pub fn create(path: Option<&Path>) -> Result<Self, AppError> {
        let out = match path {
            Some(p) => Some((p.to_path_buf(), BufWriter::new(File::create(p).map_err(|e| AppError::io(p, e))?))),
            None => None,
        };
        Ok(Self { out, lines: 0 })
    }

    /// Append one record as a line and flush it to the file.
    pub fn line<T: Serialize>(&mut self, record: &T) -> Result<(), AppError> {
        self.lines += 1;
        let Some((path, w)) = self.out.as_mut() else { return Ok(()) };
        serde_json::to_writer(&mut *w, record).map_err(|e| AppError::Failed(format!("log {}: {e}", path.display())))?;
        w.write_all(b"\n").and_then(|_| w.flush()).map_err(|e| AppError::io(path.clone(), e))
    }

    /// Number of lines written so far.
    pub fn lines(&self) -> usize {
        self.lines
    }
}

/// Plot joint trajectories (one panel line per joint) into an SVG file.
pub fn plot_joints(
    path: &Path,
    title: &str,
    series: &[(String, Vec<(f64, f64)>)],
    y_label: &str,
) -> Result<(), AppError> {
    use plotters::prelude::*;
    let fail = |e: String| AppError::Failed(format!("plot {}: {e}", path.display()));
    let root = SVGBackend::new(path, (1000, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
    let (mut t0, mut t1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for (_, pts) in series {
        for &(t, y) in pts {
            t0 = t0.min(t);
            t1 = t1.max(t);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    if !t0.is_finite() {
        (t0, t1, y0, y1) = (0.0, 1.0, -1.0, 1.0);
    }
    if t1 - t0 < 1e-9 {
        t1 = t0 + 1.0;
    }
    let pad = ((y1 - y0) * 0.05).max(1e-3);
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(t0..t1, (y0 - pad)..(y1 + pad))
        .map_err(|e| fail(e.to_string()))?;
    chart.configure_mesh().x_desc("t [s]").y_desc(y_label).draw().map_err(|e| fail(e.to_string()))?;
    for (i, (name, pts)) in series.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(2)))
            .map_err(|e| fail(e.to_string()))?
            .label(name.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| fail(e.to_string()))?;
    root.present().map_err(|e| fail(e.to_string()))?;
    Ok(())
}
