//! The report's charts, each as PNG and SVG: Pareto plots of time ratio against error,
//! roll-out error against frame, energy bar charts and labelled 2-D scatters.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::records::{Curve, EnergyBar, LinePlot, Scatter, distinct};
use crate::render::fonts;

/// One method's point on a Pareto plot.
#[derive(Debug, Clone)]
pub struct ParetoPoint {
    pub method: String,
    /// Time per frame over the ground truth's, same run.
    pub time_ratio: f64,
    pub error: f64,
    /// Measured by a peer's own tools outside the evaluation (`report::peers`): drawn as a
    /// triangle, its time ratio taken to weft's ground truth in the peer's run.
    pub peer: bool,
}

const SIZE: (u32, u32) = (760, 520);

/// Colours of [`palette`] before it repeats.
const PALETTE_LEN: usize = 10;

fn palette(i: usize) -> RGBColor {
    const C: [RGBColor; PALETTE_LEN] = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
        RGBColor(227, 119, 194),
        RGBColor(127, 127, 127),
        RGBColor(188, 189, 34),
        RGBColor(23, 190, 207),
    ];
    C[i % C.len()]
}

/// Renders `draw` to `stem.png` and `stem.svg`.
pub(crate) fn both(
    stem: &Path,
    draw: impl Fn(DrawingArea<SVGBackend, Shift>) -> crate::Result<()>,
    draw_png: impl Fn(DrawingArea<BitMapBackend, Shift>) -> crate::Result<()>,
) -> crate::Result<()> {
    both_sized(stem, SIZE, draw, draw_png)
}

/// [`both`] at `size` pixels.
fn both_sized(
    stem: &Path,
    size: (u32, u32),
    draw: impl Fn(DrawingArea<SVGBackend, Shift>) -> crate::Result<()>,
    draw_png: impl Fn(DrawingArea<BitMapBackend, Shift>) -> crate::Result<()>,
) -> crate::Result<()> {
    fonts::register();
    let png = stem.with_extension("png");
    let svg = stem.with_extension("svg");
    {
        let root = BitMapBackend::new(&png, size).into_drawing_area();
        draw_png(root)?;
    }
    let root = SVGBackend::new(&svg, size).into_drawing_area();
    draw(root)
}

/// Draws the legend and writes the chart out.
fn finish<'a, DB: DrawingBackend + 'a, CT: plotters::coord::CoordTranslate>(
    root: &DrawingArea<DB, Shift>,
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> crate::Result<()>
where
    DB::ErrorType: 'static,
{
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .position(position)
        .draw()
        .map_err(crate::Error::plot)?;
    root.present().map_err(crate::Error::plot)?;
    Ok(())
}

/// Greedy word wrap of `text` into lines `measure` finds at most `width` wide (a word
/// wider than `width` stands on a line of its own).
fn wrap(text: &str, width: u32, measure: impl Fn(&str) -> u32) -> Vec<String> {
    let mut lines: Vec<String> = Vec::new();
    for word in text.split_whitespace() {
        match lines.last_mut() {
            Some(line) if measure(&format!("{line} {word}")) <= width => {
                line.push(' ');
                line.push_str(word);
            }
            _ => lines.push(word.to_string()),
        }
    }
    lines
}

/// Draws `title` and then `notes` at the top of `root`, each wrapped to the width, and
/// returns the area below them. A long title wraps instead of running off both edges (a
/// one-line `caption` clipped the Alt-ConvLSTM roll-out plots' titles).
fn header<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    notes: &[String],
) -> crate::Result<DrawingArea<DB, Shift>>
where
    DB::ErrorType: 'static,
{
    // Browsers draw the SVG's text in their own sans-serif, often wider than the font
    // measured here: wrap with a margin.
    let width = (root.dim_in_pixel().0 as f64 * 0.9) as u32;
    let mut area = root.clone().margin(6, 0, 0, 0);
    let styles = [(title, TextStyle::from(("sans-serif", 20)))];
    let notes = notes
        .iter()
        .map(|n| (n.as_str(), ("sans-serif", 16).into_font().color(&BLACK.mix(0.8))));
    for (text, style) in styles.into_iter().chain(notes) {
        let measure = |s: &str| root.estimate_text_size(s, &style).map_or(u32::MAX, |(w, _)| w);
        for line in wrap(text, width, measure) {
            area = area.titled(&line, style.clone()).map_err(crate::Error::plot)?;
        }
    }
    Ok(area)
}

/// Log–log bounds padded by a factor on each side.
fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| *v > 0.0 && v.is_finite())
        .fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(v), b.max(v)));
    if lo > hi {
        return (0.1, 10.0);
    }
    (lo / 2.0, hi * 2.0)
}

/// Labelled ticks of a logarithmic axis from `lo` to `hi`: 1, 2 and 5 times the powers of
/// ten inside it; every integer multiple where that gives fewer than three; the powers of
/// ten alone (every n-th of them past ten) where it gives more than ten. plotters labels a
/// logarithmic axis at powers of ten only, so a range inside one decade (the loose
/// sleeve's errors, 1.6–8.1 mm with the margins) would carry no label at all.
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    log_ticks_at_most(lo, hi, 10)
}

/// [`log_ticks`] with at most `max` labels (a small panel has room for fewer).
fn log_ticks_at_most(lo: f64, hi: f64, max: usize) -> Vec<f64> {
    if !(lo > 0.0 && hi > lo && hi.is_finite()) {
        return Vec::new();
    }
    let ticks = |mantissas: &[f64]| -> Vec<f64> {
        let (k0, k1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
        (k0..=k1)
            .flat_map(|k| mantissas.iter().map(move |m| m * 10f64.powi(k)))
            .filter(|v| *v >= lo && *v <= hi)
            .collect()
    };
    let coarse = ticks(&[1.0, 2.0, 5.0]);
    // Every n-th of `v`, so that at most `max` remain.
    let thin = |v: Vec<f64>| -> Vec<f64> {
        let step = v.len().div_ceil(max.max(1)).max(1);
        v.into_iter().step_by(step).collect()
    };
    if coarse.len() < 3 {
        return thin(ticks(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]));
    }
    if coarse.len() <= max {
        return coarse;
    }
    thin(ticks(&[1.0]))
}

/// An axis tick's label, as short as its value allows: "4", "0.02", "2000" from 10⁻³ to
/// 10⁵ (three significant digits, trailing zeros dropped) and "1e-7", "2.5e6" outside.
/// plotters' default `{:.1e}` printed a tick at 4 as "4.0e0".
fn tick_label(v: f64) -> String {
    let trim = |s: &str| {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s.to_string()
        }
    };
    if v == 0.0 {
        return "0".into();
    }
    if (1e-3..1e5).contains(&v.abs()) {
        trim(&crate::records::three_significant(v))
    } else {
        let s = format!("{v:.1e}");
        match s.split_once('e') {
            Some((mantissa, exponent)) => format!("{}e{exponent}", trim(mantissa)),
            None => s,
        }
    }
}

/// Indices of the points no other point beats in both time and error.
pub fn pareto_front(points: &[ParetoPoint]) -> Vec<usize> {
    let mut front: Vec<usize> = (0..points.len())
        .filter(|&i| {
            !points.iter().enumerate().any(|(j, q)| {
                j != i
                    && q.time_ratio <= points[i].time_ratio
                    && q.error <= points[i].error
                    && (q.time_ratio < points[i].time_ratio || q.error < points[i].error)
            })
        })
        .collect();
    front.sort_by(|&a, &b| points[a].time_ratio.total_cmp(&points[b].time_ratio));
    front
}

fn pareto_on<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    title: &str,
    error_label: &str,
    points: &[ParetoPoint],
) -> crate::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(crate::Error::plot)?;
    // A zero error (a method identical to the reference) sits at the axis floor.
    let (ylo, yhi) = log_range(points.iter().map(|p| p.error));
    let (xlo, xhi) = log_range(points.iter().map(|p| p.time_ratio));
    // Room on the right for the legend (upper right), so that it hides no point.
    let xhi = xhi * (xhi / xlo).powf(0.6);
    let area = header(&root, title, &[])?;
    let mut chart = ChartBuilder::on(&area)
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(
            (xlo..xhi).log_scale(),
            (ylo..yhi).log_scale().with_key_points(log_ticks(ylo, yhi)),
        )
        .map_err(crate::Error::plot)?;
    chart
        .configure_mesh()
        .x_desc("time per frame / ground truth's (same run)")
        .y_desc(error_label)
        .x_label_formatter(&|v| tick_label(*v))
        .y_label_formatter(&|v| tick_label(*v))
        .draw()
        .map_err(crate::Error::plot)?;
    let clamp = |p: &ParetoPoint| (p.time_ratio.max(xlo), p.error.max(ylo));
    let front = pareto_front(points);
    chart
        .draw_series(LineSeries::new(
            front.iter().map(|&i| clamp(&points[i])),
            ShapeStyle::from(&BLACK.mix(0.4)).stroke_width(2),
        ))
        .map_err(crate::Error::plot)?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLACK.mix(0.4)));
    for (i, p) in points.iter().enumerate() {
        let c = palette(i);
        if p.peer {
            chart
                .draw_series(std::iter::once(TriangleMarker::new(clamp(p), 8, c.filled())))
                .map_err(crate::Error::plot)?
                .label(p.method.clone())
                .legend(move |(x, y)| TriangleMarker::new((x + 9, y), 6, c.filled()));
        } else {
            // Past the palette's ten colours a method is drawn as a ring, so no two share
            // a marker (the drape plots have eleven methods).
            let style = if i < PALETTE_LEN { c.filled() } else { c.stroke_width(3) };
            chart
                .draw_series(std::iter::once(Circle::new(clamp(p), 6, style)))
                .map_err(crate::Error::plot)?
                .label(p.method.clone())
                .legend(move |(x, y)| Circle::new((x + 9, y), 5, style));
        }
    }
    finish(&root, &mut chart, SeriesLabelPosition::UpperRight)
}

pub fn pareto(stem: &Path, title: &str, error_label: &str, points: &[ParetoPoint]) -> crate::Result<()> {
    both(
        stem,
        |r| pareto_on(r, title, error_label, points),
        |r| pareto_on(r, title, error_label, points),
    )
}

/// One panel of a [`small_multiples`] figure.
#[derive(Debug, Clone)]
pub struct Panel {
    pub title: String,
    pub error_label: String,
    /// The legend section the panel's methods are listed under (its kind of error): each
    /// section numbers its own methods' markers from the first.
    pub legend: String,
    pub points: Vec<ParetoPoint>,
}

/// A panel's size in a [`small_multiples`] figure, and its most panels on a row.
const PANEL: (u32, u32) = (380, 300);
const PANEL_COLUMNS: usize = 4;

/// How the panels of a small-multiples figure sit: (row, column) per panel, row by row,
/// each group starting a new row; and the number of rows and columns.
fn grid(groups: &[usize]) -> (Vec<(usize, usize)>, usize, usize) {
    let columns = groups.iter().copied().max().unwrap_or(1).clamp(1, PANEL_COLUMNS);
    let mut cells = Vec::new();
    let mut row = 0;
    for &n in groups.iter().filter(|n| **n > 0) {
        for k in 0..n {
            cells.push((row + k / columns, k % columns));
        }
        row += n.div_ceil(columns);
    }
    (cells, row.max(1), columns)
}

/// Draws the marker of the `i`-th method at `at`: ten colours, then the same ten as
/// rings, as triangles, as squares — so no two methods of a figure share one.
fn draw_marker<DB: DrawingBackend, CT: plotters::coord::CoordTranslate>(
    area: &DrawingArea<DB, CT>,
    i: usize,
    at: CT::From,
    size: i32,
) -> crate::Result<()>
where
    DB::ErrorType: 'static,
    CT::From: Clone + 'static,
{
    let c = palette(i);
    let e = || EmptyElement::at(at.clone());
    match (i / PALETTE_LEN) % 4 {
        0 => area.draw(&(e() + Circle::new((0, 0), size, c.filled()))),
        1 => area.draw(&(e() + Circle::new((0, 0), size, c.stroke_width(3)))),
        2 => area.draw(&(e() + TriangleMarker::new((0, 0), size + 2, c.filled()))),
        _ => area.draw(&(e() + Rectangle::new([(-size, -size), (size, size)], c.filled()))),
    }
    .map_err(crate::Error::plot)
}

fn panel_on<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, p: &Panel, methods: &[String]) -> crate::Result<()>
where
    DB::ErrorType: 'static,
{
    let (ylo, yhi) = log_range(p.points.iter().map(|q| q.error));
    let (xlo, xhi) = log_range(p.points.iter().map(|q| q.time_ratio));
    let mut chart = ChartBuilder::on(area)
        .caption(&p.title, ("sans-serif", 17))
        .margin(8)
        .margin_right(16)
        .x_label_area_size(38)
        .y_label_area_size(56)
        .build_cartesian_2d(
            (xlo..xhi).log_scale().with_key_points(log_ticks_at_most(xlo, xhi, 4)),
            (ylo..yhi).log_scale().with_key_points(log_ticks_at_most(ylo, yhi, 6)),
        )
        .map_err(crate::Error::plot)?;
    chart
        .configure_mesh()
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 14))
        .x_desc("time / ground truth's")
        .y_desc(p.error_label.as_str())
        .x_label_formatter(&|v| tick_label(*v))
        .y_label_formatter(&|v| tick_label(*v))
        .draw()
        .map_err(crate::Error::plot)?;
    let clamp = |q: &ParetoPoint| (q.time_ratio.max(xlo), q.error.max(ylo));
    chart
        .draw_series(LineSeries::new(
            pareto_front(&p.points).iter().map(|&i| clamp(&p.points[i])),
            ShapeStyle::from(&BLACK.mix(0.4)).stroke_width(2),
        ))
        .map_err(crate::Error::plot)?;
    for q in &p.points {
        let i = methods.iter().position(|m| *m == q.method).unwrap_or(0);
        draw_marker(chart.plotting_area(), i, clamp(q), 5)?;
    }
    Ok(())
}

/// A legend section: its name and its methods, in the order their markers are numbered.
type Section = (String, Vec<String>);

/// The legend's sections, in first-seen order of the panels.
fn sections(groups: &[Vec<Panel>]) -> Vec<Section> {
    let mut out: Vec<Section> = Vec::new();
    for p in groups.iter().flatten() {
        let i = match out.iter().position(|(name, _)| *name == p.legend) {
            Some(i) => i,
            None => {
                out.push((p.legend.clone(), Vec::new()));
                out.len() - 1
            }
        };
        for q in &p.points {
            if !out[i].1.contains(&q.method) {
                out[i].1.push(q.method.clone());
            }
        }
    }
    out
}

const LEGEND_ROW: i32 = 22;

/// Where the legend's texts go across `width` pixels: each section on new rows, its name
/// first, then its entries (the marker number within the section and the method), wrapped;
/// and the legend's height. Widths are estimated at 8 px a character, generously, so that
/// the legend fits however a browser draws the SVG's text.
#[allow(clippy::type_complexity)]
fn legend_layout(sections: &[Section], width: u32) -> (Vec<((i32, i32), Option<usize>, String)>, u32) {
    let chars = |s: &str| s.chars().count() as i32 * 8;
    let mut out = Vec::new();
    let mut y = 12;
    for (name, methods) in sections {
        let label = format!("{name}:");
        let indent = 10 + chars(&label) + 14;
        out.push(((10, y), None, label));
        let mut x = indent;
        for (i, m) in methods.iter().enumerate() {
            let w = 24 + chars(m);
            if x > indent && x + w > width as i32 {
                (x, y) = (indent, y + LEGEND_ROW);
            }
            out.push(((x + 6, y), Some(i), m.clone()));
            x += w;
        }
        y += LEGEND_ROW;
    }
    (out, y.max(0) as u32)
}

fn small_multiples_on<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    title: &str,
    notes: &[String],
    groups: &[Vec<Panel>],
) -> crate::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(crate::Error::plot)?;
    let area = header(&root, title, notes)?;
    let sizes: Vec<usize> = groups.iter().map(Vec::len).collect();
    let (cells, rows, columns) = grid(&sizes);
    let (panels, legend) = area.split_vertically(rows as u32 * PANEL.1);
    let areas = panels.split_evenly((rows, columns));
    let sections = sections(groups);
    for (p, (row, column)) in groups.iter().flatten().zip(cells) {
        let methods = sections
            .iter()
            .find(|(n, _)| *n == p.legend)
            .map_or(&[][..], |(_, m)| m);
        panel_on(&areas[row * columns + column], p, methods)?;
    }
    let style = TextStyle::from(("sans-serif", 15)).pos(Pos::new(HPos::Left, VPos::Center));
    for ((x, y), marker, text) in legend_layout(&sections, legend.dim_in_pixel().0).0 {
        match marker {
            Some(i) => {
                draw_marker(&legend, i, (x, y), 5)?;
                legend
                    .draw_text(&text, &style, (x + 10, y))
                    .map_err(crate::Error::plot)?;
            }
            None => legend.draw_text(&text, &style, (x, y)).map_err(crate::Error::plot)?,
        }
    }
    root.present().map_err(crate::Error::plot)?;
    Ok(())
}

/// A small-multiples figure: one speed-against-accuracy panel per group member, each
/// group starting a new row, the legend below in one section per `Panel::legend`, and
/// `notes` (what the errors measure) under the title.
pub fn small_multiples(stem: &Path, title: &str, notes: &[String], groups: &[Vec<Panel>]) -> crate::Result<()> {
    let sizes: Vec<usize> = groups.iter().map(Vec::len).collect();
    let (_, rows, columns) = grid(&sizes);
    let width = (columns as u32 * PANEL.0).max(SIZE.0);
    // The header, wrapped at about 8 px a character of the notes, 10 of the title.
    let lines = |text: &str, px: usize| text.chars().count().div_ceil((width as usize * 9 / 10 / px).max(1)) as u32;
    let header = 16 + 30 * lines(title, 10) + 26 * notes.iter().map(|n| lines(n, 8)).sum::<u32>();
    let legend = legend_layout(&sections(groups), width).1;
    let size = (width, header + rows as u32 * PANEL.1 + legend);
    both_sized(
        stem,
        size,
        |r| small_multiples_on(r, title, notes, groups),
        |r| small_multiples_on(r, title, notes, groups),
    )
}

fn rollout_on<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, title: &str, curves: &[&Curve]) -> crate::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(crate::Error::plot)?;
    let xmax = curves
        .iter()
        .flat_map(|c| c.frames.iter().copied())
        .fold(1.0f64, f64::max);
    // Each curve's values with its band's upper edge.
    let values = |c: &Curve| -> Vec<f64> {
        c.error_mm
            .iter()
            .zip(c.error_mm_sd.iter().chain(std::iter::repeat(&0.0)))
            .map(|(m, sd)| m + sd)
            .chain(c.error_mm.iter().copied())
            .filter(|v| v.is_finite())
            .collect()
    };
    let peaks: Vec<f64> = curves
        .iter()
        .map(|c| values(c).into_iter().fold(0.0, f64::max))
        .collect();
    let cap = rollout_clip(&peaks);
    let (ylo, yhi) = log_range(
        curves
            .iter()
            .flat_map(|c| values(c))
            .filter(|v| cap.is_none_or(|cap| *v <= cap)),
    );
    // A clipped axis stops at a round figure (1, 2 or 5 times a power of ten).
    let yhi = if cap.is_some() { round_up(yhi) } else { yhi };
    let mut notes = Vec::new();
    for (c, peak) in curves.iter().zip(&peaks).filter(|(_, p)| **p > yhi) {
        let leaves = c.frames.iter().zip(&c.error_mm).find(|(_, m)| **m > yhi);
        notes.push(match leaves {
            Some((frame, _)) => format!(
                "{} leaves the axis at frame {} and peaks at {} mm;",
                c.method,
                tick_label(*frame),
                tick_label(*peak)
            ),
            None => format!(
                "{}'s seed spread leaves the axis (up to {} mm);",
                c.method,
                tick_label(*peak)
            ),
        });
    }
    if !notes.is_empty() {
        notes.push(format!(
            "the axis stops at {} mm so that it does not flatten the other curves.",
            tick_label(yhi)
        ));
        notes = vec![notes.join(" ")];
    }
    let area = header(&root, title, &notes)?;
    let mut chart = ChartBuilder::on(&area)
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..xmax, (ylo..yhi).log_scale().with_key_points(log_ticks(ylo, yhi)))
        .map_err(crate::Error::plot)?;
    chart
        .configure_mesh()
        .x_desc("frame")
        .y_desc("M_rms of the frame (mm)")
        .x_label_formatter(&|v| tick_label(*v))
        .y_label_formatter(&|v| tick_label(*v))
        .draw()
        .map_err(crate::Error::plot)?;
    for (i, c) in curves.iter().enumerate() {
        let colour = palette(i);
        // The frames on the axis, in runs: a curve stops where it leaves the axis (and
        // resumes if it comes back), and so does its band.
        let on_axis: Vec<usize> = (0..c.frames.len().min(c.error_mm.len()))
            .filter(|&k| c.error_mm[k] <= yhi)
            .collect();
        let runs: Vec<&[usize]> = on_axis.chunk_by(|a, b| b - a == 1).collect();
        // A curve over seeds: its mean ± the seeds' spread as a band under the line.
        if c.error_mm_sd.len() == c.error_mm.len() {
            for run in &runs {
                let edge = |k: &usize, sign: f64| {
                    (
                        c.frames[*k],
                        (c.error_mm[*k] + sign * c.error_mm_sd[*k]).clamp(ylo, yhi),
                    )
                };
                let band: Vec<(f64, f64)> = run
                    .iter()
                    .map(|k| edge(k, 1.0))
                    .chain(run.iter().rev().map(|k| edge(k, -1.0)))
                    .collect();
                chart
                    .draw_series(std::iter::once(Polygon::new(band, colour.mix(0.18).filled())))
                    .map_err(crate::Error::plot)?;
            }
        }
        for (n, run) in runs.iter().enumerate() {
            let series = chart
                .draw_series(LineSeries::new(
                    run.iter().map(|&k| (c.frames[k], c.error_mm[k].max(ylo))),
                    ShapeStyle::from(&colour).stroke_width(2),
                ))
                .map_err(crate::Error::plot)?;
            if n == 0 {
                series
                    .label(c.method.clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2)));
            }
        }
    }
    finish(&root, &mut chart, SeriesLabelPosition::LowerRight)
}

/// The smallest of 1, 2 and 5 times a power of ten at or above `v` (> 0).
fn round_up(v: f64) -> f64 {
    let decade = 10f64.powf(v.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * decade)
        .find(|x| *x >= v * (1.0 - 1e-12))
        .unwrap_or(v)
}

/// A roll-out curve whose peak is more than this many times the median curve's peak has
/// diverged, and the axis stops short of it: the PCA + MLP simulator reaches 1e19 mm on
/// the sheet, which flattened the two embeddings (below 300 mm) against the floor.
const DIVERGED: f64 = 10.0;

/// Where a roll-out plot's axis stops, given each curve's peak: `DIVERGED` × the median
/// peak when some curve goes beyond that, else nowhere.
fn rollout_clip(peaks: &[f64]) -> Option<f64> {
    let mut sorted: Vec<f64> = peaks.iter().copied().filter(|p| p.is_finite() && *p > 0.0).collect();
    sorted.sort_by(f64::total_cmp);
    let median = *sorted.get(sorted.len().checked_sub(1)? / 2)?;
    let max = *sorted.last()?;
    (max > DIVERGED * median).then_some(DIVERGED * median)
}

pub fn rollout(stem: &Path, title: &str, curves: &[&Curve]) -> crate::Result<()> {
    both(stem, |r| rollout_on(r, title, curves), |r| rollout_on(r, title, curves))
}

fn energy_on<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, title: &str, bars: &[&EnergyBar]) -> crate::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(crate::Error::plot)?;
    let methods = distinct(bars.iter().map(|b| b.method.as_str()));
    let kinds = distinct(bars.iter().map(|b| b.kind.as_str()));
    let unit = bars.first().map_or("J", |b| b.unit.as_str());
    let xmax = bars.iter().map(|b| b.value.abs()).fold(0.0f64, f64::max).max(1e-30) * 1.4;
    let n = methods.len() as f64;
    // Horizontal bars: one row per method (first at the top), one bar per energy kind.
    let area = header(&root, title, &[])?;
    let mut chart = ChartBuilder::on(&area)
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(190)
        .build_cartesian_2d(0.0..xmax, 0.0..n)
        .map_err(crate::Error::plot)?;
    let names = methods.clone();
    chart
        .configure_mesh()
        .disable_y_mesh()
        .y_labels(methods.len() * 2 + 1)
        .y_label_formatter(&|y| {
            let row = (n - y).floor();
            let i = row as usize;
            if ((n - y) - row - 0.5).abs() < 0.26 && i < names.len() {
                names[i].to_string()
            } else {
                String::new()
            }
        })
        .x_desc(format!("mean energy ({unit})"))
        .x_label_formatter(&|v| tick_label(*v))
        .draw()
        .map_err(crate::Error::plot)?;
    let width = 0.8 / kinds.len() as f64;
    for (k, kind) in kinds.iter().enumerate() {
        let colour = palette(k);
        let rects: Vec<_> = bars
            .iter()
            .filter(|b| b.kind == *kind)
            .filter_map(|b| {
                let i = methods.iter().position(|m| *m == b.method)? as f64;
                let top = n - i - 0.1 - k as f64 * width;
                Some(Rectangle::new(
                    [(0.0, top), (b.value.abs(), top - width)],
                    colour.filled(),
                ))
            })
            .collect();
        chart
            .draw_series(rects)
            .map_err(crate::Error::plot)?
            .label(kind.to_string())
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], colour.filled()));
    }
    finish(&root, &mut chart, SeriesLabelPosition::LowerRight)
}

pub fn energy(stem: &Path, title: &str, bars: &[&EnergyBar]) -> crate::Result<()> {
    both(stem, |r| energy_on(r, title, bars), |r| energy_on(r, title, bars))
}

fn scatter_on<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, s: &Scatter) -> crate::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(crate::Error::plot)?;
    let range = |k: usize| {
        let (lo, hi) = s
            .points
            .iter()
            .map(|p| p[k])
            .filter(|v| v.is_finite())
            .fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(v), b.max(v)));
        let pad = ((hi - lo) * 0.08).max(1e-9);
        if lo > hi { -1.0..1.0 } else { lo - pad..hi + pad }
    };
    let area = header(&root, &s.title, &[])?;
    let mut chart = ChartBuilder::on(&area)
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(range(0), range(1))
        .map_err(crate::Error::plot)?;
    chart
        .configure_mesh()
        .x_desc(s.x_label.as_str())
        .y_desc(s.y_label.as_str())
        .x_label_formatter(&|v| format!("{v:.2}"))
        .y_label_formatter(&|v| format!("{v:.2}"))
        .draw()
        .map_err(crate::Error::plot)?;
    for (i, label) in distinct(s.labels.iter().map(String::as_str)).into_iter().enumerate() {
        let colour = palette(i);
        let points = s
            .points
            .iter()
            .zip(&s.labels)
            .filter(|(p, l)| l.as_str() == label && p.iter().all(|v| v.is_finite()))
            .map(|(p, _)| Circle::new((p[0], p[1]), 4, colour.filled()));
        chart
            .draw_series(points)
            .map_err(crate::Error::plot)?
            .label(label.to_string())
            .legend(move |(x, y)| Circle::new((x + 6, y), 4, colour.filled()));
    }
    finish(&root, &mut chart, SeriesLabelPosition::UpperRight)
}

/// A labelled 2-D scatter, one colour per label.
pub fn scatter(stem: &Path, s: &Scatter) -> crate::Result<()> {
    both(stem, |r| scatter_on(r, s), |r| scatter_on(r, s))
}

fn lines_on<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, p: &LinePlot) -> crate::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(crate::Error::plot)?;
    let finite = |v: &&f64| v.is_finite();
    let (xlo, xhi) = p
        .series
        .iter()
        .flat_map(|s| s.x.iter().filter(finite).copied())
        .fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(v), b.max(v)));
    let (xlo, xhi) = if xlo < xhi { (xlo, xhi) } else { (0.0, 1.0) };
    let ys = || p.series.iter().flat_map(|s| s.y.iter().filter(finite).copied());
    let e = |e| crate::Error::plot(e);
    let area = header(&root, &p.title, &[])?;
    let mut builder = ChartBuilder::on(&area);
    builder.margin(12).x_label_area_size(45).y_label_area_size(70);
    // The two axis kinds are different types; draw the same series on either.
    macro_rules! draw {
        ($chart:expr, $floor:expr) => {{
            let mut chart = $chart;
            chart
                .configure_mesh()
                .x_desc(p.x_label.as_str())
                .x_label_formatter(&|v| tick_label(*v))
                .y_desc(p.y_label.as_str())
                .y_label_formatter(&|v| tick_label(*v))
                .draw()
                .map_err(e)?;
            for (i, s) in p.series.iter().enumerate() {
                let colour = palette(i);
                chart
                    .draw_series(LineSeries::new(
                        s.x.iter()
                            .zip(&s.y)
                            .filter(|(x, y)| x.is_finite() && y.is_finite())
                            .map(|(x, y)| (*x, y.max($floor))),
                        ShapeStyle::from(&colour).stroke_width(2),
                    ))
                    .map_err(e)?
                    .label(s.label.clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2)));
            }
            finish(&root, &mut chart, SeriesLabelPosition::UpperLeft)
        }};
    }
    if p.log_y {
        let (lo, hi) = log_range(ys());
        draw!(
            builder
                .build_cartesian_2d(xlo..xhi, (lo..hi).log_scale().with_key_points(log_ticks(lo, hi)))
                .map_err(e)?,
            lo
        )
    } else {
        let (lo, hi) = ys().fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(v), b.max(v)));
        let (lo, hi) = if lo < hi { (lo, hi) } else { (lo - 1.0, lo + 1.0) };
        let pad = 0.06 * (hi - lo);
        draw!(
            builder.build_cartesian_2d(xlo..xhi, lo - pad..hi + pad).map_err(e)?,
            f64::MIN
        )
    }
}

/// A line chart of several series (NNWarp's trajectory and extrapolation figures).
pub fn lines(stem: &Path, p: &LinePlot) -> crate::Result<()> {
    both(stem, |r| lines_on(r, p), |r| lines_on(r, p))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_are_short_and_keep_their_value() {
        let cases = [
            (4.0, "4"),
            (0.02, "0.02"),
            (0.001, "0.001"),
            (2000.0, "2000"),
            (0.25, "0.25"),
            (-1.5, "-1.5"),
            (12345.0, "12345"),
            (1e-7, "1e-7"),
            (2.5e-8, "2.5e-8"),
            (3e6, "3e6"),
            (0.0, "0"),
        ];
        for (v, label) in cases {
            assert_eq!(tick_label(v), label, "{v}");
            let back: f64 = label.parse().unwrap();
            assert!((back - v).abs() <= 1e-12 * v.abs(), "{label} reads back as {v}");
        }
    }

    #[test]
    fn log_axes_are_labelled_inside_one_decade_and_sparsely_across_many() {
        let close = |a: &[f64], b: &[f64]| a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9 * y);
        // Inside one decade: every integer mantissa.
        let t = log_ticks(1.59, 8.14);
        assert!(close(&t, &[2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]), "{t:?}");
        // Two decades: 1, 2, 5.
        let t = log_ticks(0.05, 3.0);
        assert!(close(&t, &[0.05, 0.1, 0.2, 0.5, 1.0, 2.0]), "{t:?}");
        // Twelve decades: at most ten labels, all powers of ten.
        let t = log_ticks(1e-9, 1e3);
        assert!(t.len() <= 10 && t.len() >= 5, "{t:?}");
        assert!(t.iter().all(|v| (v.log10() - v.log10().round()).abs() < 1e-9), "{t:?}");
        // No range, no ticks.
        assert!(log_ticks(0.0, 1.0).is_empty() && log_ticks(2.0, 1.0).is_empty());
    }

    #[test]
    fn pareto_front_keeps_exactly_the_undominated_points() {
        let p = |m: &str, t, e| ParetoPoint {
            method: m.into(),
            time_ratio: t,
            error: e,
            peer: false,
        };
        let points = vec![
            p("a", 1.0, 1.0),
            p("b", 0.5, 2.0),
            p("c", 2.0, 0.5),
            p("d", 1.5, 1.5),
            p("e", 0.5, 3.0),
        ];
        // d is beaten by a; e is beaten by b (same time, more error).
        assert_eq!(pareto_front(&points), [1, 0, 2]);
    }

    #[test]
    fn a_roll_out_axis_stops_short_of_a_diverged_curve_only() {
        // The sheet's embeddings peak near 300 mm, the PCA + MLP simulator at 1e19 mm.
        assert_eq!(rollout_clip(&[230.0, 120.0, 1.8e19]), Some(2300.0));
        // Solver variants a few times apart are all drawn whole.
        assert_eq!(rollout_clip(&[1.9, 4.9, 4.6, 2.8]), None);
        assert_eq!(rollout_clip(&[5.0]), None);
        assert_eq!(rollout_clip(&[]), None);
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b;
        assert!(close(round_up(7248.0), 10000.0) && close(round_up(0.15), 0.2) && close(round_up(2.0), 2.0));
    }

    #[test]
    fn titles_wrap_into_lines_that_fit_and_keep_every_word() {
        let title = "altconv / limb-jiggle (test): roll-out error at each step, mean over vertices and sequences";
        let measure = |s: &str| 9 * s.chars().count() as u32;
        let lines = wrap(title, 400, measure);
        assert!(lines.len() > 1, "{lines:?}");
        assert!(lines.iter().all(|l| measure(l) <= 400), "{lines:?}");
        assert_eq!(lines.join(" "), title);
        assert_eq!(wrap("short", 400, measure), ["short"]);
    }

    #[test]
    fn small_multiples_start_each_group_on_a_new_row() {
        // Two simulation panels, then ten reconstruction panels: rows of at most four.
        let (cells, rows, columns) = grid(&[2, 10]);
        assert_eq!((rows, columns), (4, 4));
        assert_eq!(cells[..3], [(0, 0), (0, 1), (1, 0)]);
        assert_eq!(cells[11], (3, 1));
        let (cells, rows, columns) = grid(&[1]);
        assert_eq!((cells, rows, columns), (vec![(0, 0)], 1, 1));
    }
}
