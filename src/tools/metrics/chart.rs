//! PNG charts of one measure against another (speed against accuracy), with the Pareto front
//! drawn in. The CSV with the same numbers is written beside each chart by its caller.

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;

/// A labelled point of a chart.
#[derive(Clone, Debug)]
pub struct ChartPoint {
    /// Label drawn beside the point (a method or a setting).
    pub label: String,
    /// x value.
    pub x: f64,
    /// y value.
    pub y: f64,
    /// Highlight (the default choice).
    pub chosen: bool,
}

/// A scatter chart: each point labelled, the Pareto front (lower x and lower y are better)
/// joined by a line.
#[derive(Clone, Debug)]
pub struct Chart {
    /// Title at the top.
    pub title: String,
    /// x axis label.
    pub x_label: String,
    /// y axis label.
    pub y_label: String,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// Logarithmic y axis.
    pub log_y: bool,
    /// The points.
    pub points: Vec<ChartPoint>,
}

/// Why a chart could not be drawn or written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ChartError {
    /// Plotting failed.
    #[error("drawing chart {path}: {message}")]
    Draw {
        /// The chart's file.
        path: String,
        /// What plotters said.
        message: String,
    },
    /// Writing the PNG failed (nothing is left under its name, see
    /// [`crate::tools::fly::write_atomic`]).
    #[error(transparent)]
    Write(#[from] crate::tools::fly::WriteError),
}

/// Indices of the points no other point beats in both x and y (lower is better), by x.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let rows: Vec<Vec<f64>> = points.iter().map(|&(x, y)| vec![x, y]).collect();
    let mut front = pareto_front_n(&rows);
    front.sort_by(|&a, &b| points[a].0.total_cmp(&points[b].0));
    front
}

/// Indices of the rows that no other row dominates (at most as large in every measure and
/// smaller in one; lower is better in every column).
pub fn pareto_front_n(rows: &[Vec<f64>]) -> Vec<usize> {
    let dominates = |a: &[f64], b: &[f64]| {
        a.iter().zip(b).all(|(x, y)| x <= y) && a.iter().zip(b).any(|(x, y)| x < y)
    };
    (0..rows.len())
        .filter(|&i| {
            !rows
                .iter()
                .enumerate()
                .any(|(j, r)| j != i && dominates(r, &rows[i]))
        })
        .collect()
}

static FONT: Once = Once::new();

fn register_font() {
    FONT.call_once(|| {
        // DejaVu Sans (Bitstream Vera licence, see fonts/LICENSE-DejaVu.txt), compiled in so that
        // charts need no system fonts.
        let bytes: &'static [u8] = include_bytes!("fonts/DejaVuSans.ttf");
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, bytes);
    });
}

/// A tick label with a few significant digits and no float noise.
fn short_number(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if a >= 100.0 {
        format!("{v:.0}")
    } else if a >= 1.0 {
        format!("{v:.2}")
            .trim_end_matches('0')
            .trim_end_matches('.')
            .into()
    } else {
        let digits = (-a.log10()).ceil() as usize + 1;
        format!("{v:.digits$}")
            .trim_end_matches('0')
            .trim_end_matches('.')
            .into()
    }
}

/// Whether values span enough of a range (a factor of 5) for a log axis to show ticks; a
/// narrower range is drawn on a linear axis.
fn spans_decades(values: impl Iterator<Item = f64>) -> bool {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::MAX, f64::MIN), |(l, h), v| (l.min(v), h.max(v)));
    lo <= hi && hi / lo >= 5.0
}

fn range(values: impl Iterator<Item = f64>, log: bool) -> (f64, f64) {
    let (mut lo, mut hi) = values
        .filter(|v| v.is_finite() && (!log || *v > 0.0))
        .fold((f64::MAX, f64::MIN), |(l, h), v| (l.min(v), h.max(v)));
    if lo > hi {
        (lo, hi) = (1.0, 10.0);
    }
    if log {
        (lo / 1.6, hi * 1.6)
    } else {
        let pad = ((hi - lo) * 0.12).max(hi.abs() * 0.05).max(1e-9);
        (
            (lo - pad).min(if lo >= 0.0 { 0.0 } else { lo - pad }),
            hi + pad,
        )
    }
}

impl Chart {
    /// Draws the chart into a `width` x `height` PNG at `path`.
    pub fn write_png(&self, path: &Path, width: u32, height: u32) -> Result<(), ChartError> {
        self.write_png_with_front(path, width, height, |_| true)
    }

    /// Draws the chart like [`Chart::write_png`], with the Pareto front taken over the points
    /// for which `on_front` holds only. The other points are drawn all the same but neither
    /// join nor hide the front: runs that failed, say, whose cost is real but whose accuracy
    /// is not.
    pub fn write_png_with_front(
        &self,
        path: &Path,
        width: u32,
        height: u32,
        on_front: impl Fn(&ChartPoint) -> bool,
    ) -> Result<(), ChartError> {
        register_font();
        let mut buf = vec![255u8; width as usize * height as usize * 3];
        let err = |e: String| ChartError::Draw {
            path: path.display().to_string(),
            message: e,
        };
        {
            let root = BitMapBackend::with_buffer(&mut buf, (width, height)).into_drawing_area();
            root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
            let log_x = self.log_x && spans_decades(self.points.iter().map(|p| p.x));
            let log_y = self.log_y && spans_decades(self.points.iter().map(|p| p.y));
            let xr = range(self.points.iter().map(|p| p.x), log_x);
            let yr = range(self.points.iter().map(|p| p.y), log_y);
            macro_rules! draw {
                ($x:expr, $y:expr) => {{
                    let mut chart = ChartBuilder::on(&root)
                        .caption(&self.title, ("sans-serif", 20))
                        .margin(16)
                        .margin_right(150)
                        .x_label_area_size(44)
                        .y_label_area_size(64)
                        .build_cartesian_2d($x, $y)
                        .map_err(|e| err(e.to_string()))?;
                    chart
                        .configure_mesh()
                        .x_desc(&self.x_label)
                        .y_desc(&self.y_label)
                        .label_style(("sans-serif", 13))
                        .x_labels(8)
                        .y_labels(8)
                        .light_line_style(RGBColor(238, 238, 238))
                        .x_label_formatter(&|v| short_number(*v))
                        .y_label_formatter(&|v| short_number(*v))
                        .axis_desc_style(("sans-serif", 15))
                        .draw()
                        .map_err(|e| err(e.to_string()))?;
                    let xy: Vec<(f64, f64)> = self
                        .points
                        .iter()
                        .filter(|p| on_front(p))
                        .map(|p| (p.x, p.y))
                        .collect();
                    let front: Vec<(f64, f64)> =
                        pareto_front(&xy).into_iter().map(|i| xy[i]).collect();
                    chart
                        .draw_series(LineSeries::new(
                            front,
                            RGBColor(120, 170, 120).stroke_width(2),
                        ))
                        .map_err(|e| err(e.to_string()))?
                        .label("Pareto front")
                        .legend(|(x, y)| {
                            PathElement::new(vec![(x, y), (x + 18, y)], RGBColor(120, 170, 120))
                        });
                    let texts: Vec<String> = self
                        .points
                        .iter()
                        .map(|p| {
                            if p.chosen && p.label != "default" {
                                format!("{} (default)", p.label)
                            } else {
                                p.label.clone()
                            }
                        })
                        .collect();
                    let anchors: Vec<(i32, i32)> = self
                        .points
                        .iter()
                        .map(|p| chart.backend_coord(&(p.x, p.y)))
                        .collect();
                    let widths: Vec<i32> = texts
                        .iter()
                        .map(|t| LABEL_CHAR_PX * t.chars().count() as i32)
                        .collect();
                    let offsets = place_labels(&anchors, &widths);
                    for ((p, text), offset) in self.points.iter().zip(texts).zip(offsets) {
                        let color = if p.chosen {
                            RGBColor(200, 40, 40)
                        } else {
                            RGBColor(40, 70, 160)
                        };
                        let size = if p.chosen { 7 } else { 5 };
                        chart
                            .draw_series(std::iter::once(
                                EmptyElement::at((p.x, p.y))
                                    + Circle::new((0, 0), size, color.filled())
                                    + Text::new(
                                        text,
                                        offset,
                                        ("sans-serif", 13).into_font().color(&color),
                                    ),
                            ))
                            .map_err(|e| err(e.to_string()))?;
                    }
                    // The lower left holds no point of a speed-against-accuracy chart whose
                    // axes start at 0 (a point there would beat every other).
                    chart
                        .configure_series_labels()
                        .position(SeriesLabelPosition::LowerLeft)
                        .background_style(WHITE.mix(0.8))
                        .border_style(BLACK)
                        .label_font(("sans-serif", 13))
                        .draw()
                        .map_err(|e| err(e.to_string()))?;
                }};
            }
            match (log_x, log_y) {
                (true, true) => draw!((xr.0..xr.1).log_scale(), (yr.0..yr.1).log_scale()),
                (true, false) => draw!((xr.0..xr.1).log_scale(), yr.0..yr.1),
                (false, true) => draw!(xr.0..xr.1, (yr.0..yr.1).log_scale()),
                (false, false) => draw!(xr.0..xr.1, yr.0..yr.1),
            }
            root.present().map_err(|e| err(e.to_string()))?;
        }
        let img = image::RgbImage::from_raw(width, height, buf).expect("buffer holds the image");
        Ok(crate::tools::fly::write_png(path, &img)?)
    }
}

/// Width of a label's character at the charts' 13-point font, pixels (about; a label's box is
/// its characters times this).
const LABEL_CHAR_PX: i32 = 7;
/// Height of a label's box, pixels.
const LABEL_HEIGHT_PX: i32 = 15;

/// Where each point's label goes, as an offset in pixels from the point (`anchors`, the points
/// on the chart) to the label's top left corner, for labels `widths` pixels wide: above and to
/// the right of its point unless that box overlaps a label placed before it or another point,
/// then the first free one of: below right, higher, lower, and the same to the left (the first
/// one if none is free). Points are placed in the order given.
pub fn place_labels(anchors: &[(i32, i32)], widths: &[i32]) -> Vec<(i32, i32)> {
    const POINT_PX: i32 = 6;
    let overlaps = |a: (i32, i32, i32, i32), b: (i32, i32, i32, i32)| {
        a.0 < b.2 && b.0 < a.2 && a.1 < b.3 && b.1 < a.3
    };
    // A point far off the chart (a value the axes cannot place maps to the ends of i32) must
    // not overflow the boxes' sums.
    const FAR: i32 = 1 << 20;
    let anchors: Vec<(i32, i32)> = anchors
        .iter()
        .map(|&(x, y)| (x.clamp(-FAR, FAR), y.clamp(-FAR, FAR)))
        .collect();
    let anchors = &anchors[..];
    let mut placed: Vec<(i32, i32, i32, i32)> = Vec::new();
    let mut out = Vec::with_capacity(anchors.len());
    for (i, (&(x, y), &w)) in anchors.iter().zip(widths).enumerate() {
        let w = w.clamp(0, FAR);
        let h = LABEL_HEIGHT_PX;
        let candidates = [
            (8, -16),
            (8, 2),
            (8, -16 - h),
            (8, 2 + h),
            (-8 - w, -16),
            (-8 - w, 2),
            (-8 - w, -16 - h),
            (-8 - w, 2 + h),
        ];
        let free = |&(dx, dy): &(i32, i32)| {
            let b = (x + dx, y + dy, x + dx + w, y + dy + h);
            !placed.iter().any(|&p| overlaps(p, b))
                && !anchors.iter().enumerate().any(|(j, &(px, py))| {
                    j != i
                        && overlaps(
                            (px - POINT_PX, py - POINT_PX, px + POINT_PX, py + POINT_PX),
                            b,
                        )
                })
        };
        let (dx, dy) = candidates
            .iter()
            .copied()
            .find(|c| free(c))
            .unwrap_or(candidates[0]);
        placed.push((x + dx, y + dy, x + dx + w, y + dy + h));
        out.push((dx, dy));
    }
    out
}

/// A named line of a [`LineChart`].
#[derive(Clone, Debug)]
pub struct Series {
    /// Name in the legend.
    pub name: String,
    /// The points, joined in this order. Points that are not finite (or not positive on a log
    /// axis) are left out.
    pub points: Vec<(f64, f64)>,
}

/// A chart of lines, one colour per series and a legend: a measure against a setting (an error
/// against a time step, say), where a Pareto front would mean nothing. Reference lines (a
/// threshold, a limit) are series of two points.
#[derive(Clone, Debug)]
pub struct LineChart {
    /// Title at the top.
    pub title: String,
    /// x axis label.
    pub x_label: String,
    /// y axis label.
    pub y_label: String,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// Logarithmic y axis.
    pub log_y: bool,
    /// The lines.
    pub series: Vec<Series>,
}

/// Colours of the series of a [`LineChart`], in turn.
const PALETTE: [RGBColor; 8] = [
    RGBColor(200, 40, 40),
    RGBColor(40, 70, 160),
    RGBColor(30, 140, 60),
    RGBColor(130, 130, 130),
    RGBColor(200, 130, 0),
    RGBColor(140, 60, 160),
    RGBColor(0, 150, 160),
    RGBColor(90, 60, 30),
];

impl LineChart {
    fn drawable(&self, s: &Series) -> Vec<(f64, f64)> {
        s.points
            .iter()
            .copied()
            .filter(|&(x, y)| {
                x.is_finite()
                    && y.is_finite()
                    && (!self.log_x || x > 0.0)
                    && (!self.log_y || y > 0.0)
            })
            .collect()
    }

    /// Draws the chart into a `width` x `height` PNG at `path`.
    pub fn write_png(&self, path: &Path, width: u32, height: u32) -> Result<(), ChartError> {
        register_font();
        let mut buf = vec![255u8; width as usize * height as usize * 3];
        let err = |e: String| ChartError::Draw {
            path: path.display().to_string(),
            message: e,
        };
        {
            let root = BitMapBackend::with_buffer(&mut buf, (width, height)).into_drawing_area();
            root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
            let lines: Vec<Vec<(f64, f64)>> =
                self.series.iter().map(|s| self.drawable(s)).collect();
            let xr = range(lines.iter().flatten().map(|p| p.0), self.log_x);
            let yr = range(lines.iter().flatten().map(|p| p.1), self.log_y);
            macro_rules! draw {
                ($x:expr, $y:expr) => {{
                    let mut chart = ChartBuilder::on(&root)
                        .caption(&self.title, ("sans-serif", 20))
                        .margin(16)
                        .x_label_area_size(44)
                        .y_label_area_size(64)
                        .build_cartesian_2d($x, $y)
                        .map_err(|e| err(e.to_string()))?;
                    chart
                        .configure_mesh()
                        .x_desc(&self.x_label)
                        .y_desc(&self.y_label)
                        .label_style(("sans-serif", 13))
                        .x_labels(8)
                        .y_labels(8)
                        .light_line_style(RGBColor(238, 238, 238))
                        .x_label_formatter(&|v| short_number(*v))
                        .y_label_formatter(&|v| short_number(*v))
                        .axis_desc_style(("sans-serif", 15))
                        .draw()
                        .map_err(|e| err(e.to_string()))?;
                    for (i, (s, pts)) in self.series.iter().zip(&lines).enumerate() {
                        let color = PALETTE[i % PALETTE.len()];
                        chart
                            .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
                            .map_err(|e| err(e.to_string()))?
                            .label(s.name.clone())
                            .legend(move |(x, y)| {
                                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
                            });
                        if pts.len() > 2 {
                            chart
                                .draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))
                                .map_err(|e| err(e.to_string()))?;
                        }
                    }
                    chart
                        .configure_series_labels()
                        .position(SeriesLabelPosition::UpperLeft)
                        .background_style(WHITE.mix(0.85))
                        .border_style(BLACK)
                        .label_font(("sans-serif", 13))
                        .draw()
                        .map_err(|e| err(e.to_string()))?;
                }};
            }
            match (self.log_x, self.log_y) {
                (true, true) => draw!((xr.0..xr.1).log_scale(), (yr.0..yr.1).log_scale()),
                (true, false) => draw!((xr.0..xr.1).log_scale(), yr.0..yr.1),
                (false, true) => draw!(xr.0..xr.1, (yr.0..yr.1).log_scale()),
                (false, false) => draw!(xr.0..xr.1, yr.0..yr.1),
            }
            root.present().map_err(|e| err(e.to_string()))?;
        }
        let img = image::RgbImage::from_raw(width, height, buf).expect("buffer holds the image");
        Ok(crate::tools::fly::write_png(path, &img)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_of_nearby_points_do_not_overlap() {
        // Three points a few pixels apart, as the view distances and the default of bench lod's
        // front at 1920x1080 stood, and one far from them.
        let anchors = [(300, 66), (318, 66), (345, 66), (600, 400)];
        let widths = [70, 120, 70, 50];
        let offsets = place_labels(&anchors, &widths);
        assert_eq!(offsets[3], (8, -16), "a lone point keeps the usual place");
        assert!(offsets[..3].iter().any(|&o| o != (8, -16)));
        // Points the axes map to the ends of the coordinates do not overflow.
        let far = place_labels(&[(i32::MAX, i32::MIN), (i32::MIN, 0)], &[i32::MAX, 40]);
        assert_eq!(far.len(), 2);
        let boxes: Vec<(i32, i32, i32, i32)> = anchors
            .iter()
            .zip(&widths)
            .zip(&offsets)
            .map(|((&(x, y), &w), &(dx, dy))| {
                (x + dx, y + dy, x + dx + w, y + dy + LABEL_HEIGHT_PX)
            })
            .collect();
        // No label over another, nor over a point other than its own.
        for (i, b) in boxes.iter().enumerate() {
            for (j, &(px, py)) in anchors.iter().enumerate() {
                let inside = b.0 < px + 6 && px - 6 < b.2 && b.1 < py + 6 && py - 6 < b.3;
                assert!(i == j || !inside, "label {i} covers point {j}");
            }
        }
        for i in 0..boxes.len() {
            for j in 0..i {
                let (a, b) = (boxes[i], boxes[j]);
                let overlap = a.0 < b.2 && b.0 < a.2 && a.1 < b.3 && b.1 < a.3;
                assert!(!overlap, "labels {i} and {j} overlap: {a:?} {b:?}");
            }
        }
    }

    #[test]
    fn pareto_front_keeps_what_nothing_beats() {
        let pts = [(1.0, 5.0), (2.0, 3.0), (3.0, 4.0), (4.0, 1.0), (2.0, 3.0)];
        // (3, 4) is beaten by (2, 3); the two (2, 3) tie and both stay.
        assert_eq!(pareto_front(&pts), vec![0, 1, 4, 3]);
    }

    #[test]
    fn charts_are_written() {
        let dir = tempfile::tempdir().unwrap();
        let chart = Chart {
            title: "test".into(),
            x_label: "ms".into(),
            y_label: "m".into(),
            log_x: true,
            log_y: false,
            points: vec![
                ChartPoint {
                    label: "a".into(),
                    x: 0.1,
                    y: 2.0,
                    chosen: false,
                },
                ChartPoint {
                    label: "b".into(),
                    x: 1.0,
                    y: 1.0,
                    chosen: true,
                },
            ],
        };
        let file = dir.path().join("c.png");
        chart.write_png(&file, 400, 300).unwrap();
        let img = image::open(&file).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (400, 300));
        // Something besides the white background was drawn, including the highlighted point.
        assert!(img.pixels().any(|p| p.0 == [200, 40, 40]));
    }

    #[test]
    fn line_charts_are_written_and_skip_what_they_cannot_draw() {
        let dir = tempfile::tempdir().unwrap();
        let chart = LineChart {
            title: "lines".into(),
            x_label: "s".into(),
            y_label: "m".into(),
            log_x: true,
            log_y: true,
            series: vec![
                Series {
                    name: "a".into(),
                    points: vec![(0.01, 1.0), (0.1, 10.0), (1.0, f64::INFINITY), (2.0, 0.0)],
                },
                Series {
                    name: "b".into(),
                    points: vec![(0.01, 3.0), (1.0, 3.0)],
                },
            ],
        };
        let file = dir.path().join("l.png");
        chart.write_png(&file, 400, 300).unwrap();
        let img = image::open(&file).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (400, 300));
        assert!(img.pixels().any(|p| p.0 == [200, 40, 40]));
        assert!(img.pixels().any(|p| p.0 == [40, 70, 160]));
    }
}
