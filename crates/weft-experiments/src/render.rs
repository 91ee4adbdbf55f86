//! Software rendering of a triangle mesh coloured by a per-vertex value: an orthographic
//! view, faces painted back to front (painter's algorithm), each face's colour the
//! viridis colour of its vertices' mean position on the colour bar, shaded by how
//! squarely it faces the camera. Errors are drawn on a linear bar in millimetres
//! ([`error_png`]); a positive parameter spanning decades, such as a learned per-vertex
//! μ, on a logarithmic bar in its own unit ([`log_scale_png`]).

use std::path::Path;

use nalgebra::Vector3;
use plotters::prelude::*;
use plotters::style::colors::colormaps::{ColorMap, ViridisRGB};

/// Orthographic camera: the direction it looks along and the world's up axis.
#[derive(Debug, Clone, Copy)]
pub struct View {
    look: [f64; 3],
    up: [f64; 3],
}

impl View {
    /// A sheet hanging in the XZ plane, seen from −Y, slightly from the left and above.
    pub const FRONT: View = View {
        look: [0.35, 1.0, -0.3],
        up: [0.0, 0.0, 1.0],
    };
    /// The beam along x, clamped at x = 0, seen from the side and above.
    pub const BEAM: View = View {
        look: [0.3, 1.0, -0.45],
        up: [0.0, 0.0, 1.0],
    };
    /// A sheet lying in the XY plane, seen from above at an angle.
    pub const TOP: View = View {
        look: [0.2, 0.6, -1.0],
        up: [0.0, 1.0, 0.0],
    };
}

const WIDTH: u32 = 480;
const HEIGHT: u32 = 420;
const BAR: i32 = 70;

/// The viridis colour of each vertex error (m) on a scale from 0 to `scale` (m): the
/// colours of [`error_png`], for a PLY file a user can open in any mesh viewer.
pub fn error_colors(errors: &[f64], scale: f64) -> Vec<[u8; 3]> {
    bar_colors(&errors.iter().map(|&e| e / scale.max(1e-300)).collect::<Vec<_>>())
}

/// The viridis colour of each position on the colour bar (0 at the bottom, 1 at the top;
/// clamped).
pub fn bar_colors(fractions: &[f64]) -> Vec<[u8; 3]> {
    fractions
        .iter()
        .map(|&t| {
            let c = ViridisRGB.get_color_normalized(t.clamp(0.0, 1.0), 0.0, 1.0);
            [c.0, c.1, c.2]
        })
        .collect()
}

/// The colour bar's labels: its bottom and top values and their unit.
#[derive(Debug, Clone)]
pub struct ColourBar {
    pub bottom: String,
    pub top: String,
    pub unit: String,
}

/// Renders `positions` (flat, m) with `faces`, coloured by `errors` (m per vertex) on a
/// scale from 0 to `scale` (m), to a PNG at `path`; the bar is labelled in millimetres.
pub fn error_png(
    path: &Path,
    positions: &[f64],
    faces: &[[usize; 3]],
    errors: &[f64],
    scale: f64,
    title: &str,
    view: View,
) -> crate::Result<()> {
    let fractions: Vec<f64> = errors.iter().map(|&e| e / scale).collect();
    let bar = ColourBar {
        bottom: format!("{:.3}", 0.0),
        top: format!("{:.3}", 1e3 * scale),
        unit: "mm".into(),
    };
    shaded_png(path, positions, faces, &fractions, &bar, title, view)
}

/// Where each of `values` (positive) sits on a logarithmic bar from the smallest to the
/// largest of them, and that bar's labels in `unit`: a learned per-vertex μ spans several
/// decades, which a linear bar shows as one colour and a few outliers.
pub fn log_scale(values: &[f64], unit: &str) -> crate::Result<(Vec<f64>, ColourBar)> {
    if let Some(bad) = values.iter().find(|v| !(v.is_finite() && **v > 0.0)) {
        return Err(crate::Error::Invalid(format!(
            "a logarithmic colour bar needs positive, finite values; got {bad}"
        )));
    }
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(0.0f64, f64::max);
    let span = (hi / lo).ln();
    let fractions = values
        .iter()
        .map(|v| if span > 0.0 { (v / lo).ln() / span } else { 0.5 })
        .collect();
    let label = |v: f64| format!("{v:.1e}");
    Ok((
        fractions,
        ColourBar {
            bottom: label(lo),
            top: label(hi),
            unit: format!("{unit} (log)"),
        },
    ))
}

/// [`error_png`] for `values` on a logarithmic bar ([`log_scale`]).
pub fn log_scale_png(
    path: &Path,
    positions: &[f64],
    faces: &[[usize; 3]],
    values: &[f64],
    unit: &str,
    title: &str,
    view: View,
) -> crate::Result<()> {
    let (fractions, bar) = log_scale(values, unit)?;
    shaded_png(path, positions, faces, &fractions, &bar, title, view)
}

/// Renders `positions` (flat, m) with `faces`, each vertex at `fractions` of the way up the
/// colour bar `bar`, to a PNG at `path`.
fn shaded_png(
    path: &Path,
    positions: &[f64],
    faces: &[[usize; 3]],
    fractions: &[f64],
    bar: &ColourBar,
    title: &str,
    view: View,
) -> crate::Result<()> {
    fonts::register();
    let f = Vector3::from(view.look).normalize();
    let right = f.cross(&Vector3::from(view.up)).normalize();
    let up = right.cross(&f);
    let p = |v: usize| Vector3::new(positions[3 * v], positions[3 * v + 1], positions[3 * v + 2]);
    let screen: Vec<(f64, f64)> = (0..positions.len() / 3)
        .map(|v| (p(v).dot(&right), p(v).dot(&up)))
        .collect();
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in &screen {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    let (plot_w, plot_h) = ((WIDTH as i32 - BAR - 20) as f64, (HEIGHT as i32 - 60) as f64);
    let zoom = (plot_w / (x1 - x0).max(1e-12)).min(plot_h / (y1 - y0).max(1e-12));
    let to_px = |(x, y): (f64, f64)| {
        let cx = 10.0 + 0.5 * (plot_w - zoom * (x1 - x0));
        let cy = 40.0 + 0.5 * (plot_h - zoom * (y1 - y0));
        ((cx + zoom * (x - x0)) as i32, (cy + zoom * (y1 - y)) as i32)
    };
    // Back to front: largest depth along the view direction first.
    let mut order: Vec<(f64, usize)> = faces
        .iter()
        .enumerate()
        .map(|(i, t)| (t.iter().map(|&v| p(v).dot(&f)).sum::<f64>(), i))
        .collect();
    order.sort_by(|a, b| b.0.total_cmp(&a.0));

    let root = BitMapBackend::new(path, (WIDTH, HEIGHT)).into_drawing_area();
    root.fill(&WHITE)?;
    root.draw(&Text::new(title.to_string(), (10, 10), ("sans-serif", 16).into_font()))?;
    for (_, i) in order {
        let t = faces[i];
        let n = (p(t[1]) - p(t[0])).cross(&(p(t[2]) - p(t[0])));
        let facing = if n.norm() > 0.0 {
            n.normalize().dot(&f).abs()
        } else {
            0.0
        };
        let e = t.iter().map(|&v| fractions[v]).sum::<f64>() / 3.0;
        let c = ViridisRGB.get_color_normalized(e.clamp(0.0, 1.0), 0.0, 1.0);
        let shade = 0.45 + 0.55 * facing;
        let rgb = RGBColor(
            (c.0 as f64 * shade) as u8,
            (c.1 as f64 * shade) as u8,
            (c.2 as f64 * shade) as u8,
        );
        let pts: Vec<(i32, i32)> = t.iter().map(|&v| to_px(screen[v])).collect();
        root.draw(&Polygon::new(pts, rgb.filled()))?;
    }
    // Colour bar with its bottom and top labels and its unit.
    let (bx, by, bh) = (WIDTH as i32 - BAR + 10, 50, HEIGHT as i32 - 100);
    for k in 0..bh {
        let c = ViridisRGB.get_color_normalized(1.0 - k as f64 / bh as f64, 0.0, 1.0);
        root.draw(&Rectangle::new([(bx, by + k), (bx + 14, by + k + 1)], c.filled()))?;
    }
    for (text, at) in [
        (&bar.top, (bx + 17, by - 5)),
        (&bar.bottom, (bx + 17, by + bh - 8)),
        (&bar.unit, (bx, by + bh + 10)),
    ] {
        root.draw(&Text::new(text.clone(), at, ("sans-serif", 12).into_font()))?;
    }
    root.present()?;
    Ok(())
}

/// Fonts for PNG text: DejaVu Sans, embedded, so no system font is needed.
pub mod fonts {
    use std::sync::Once;

    static REGISTER: Once = Once::new();

    pub fn register() {
        REGISTER.call_once(|| {
            // Registering an embedded, valid TTF cannot fail but for a malformed font.
            let _ = plotters::style::register_font(
                "sans-serif",
                plotters::style::FontStyle::Normal,
                dejavu::sans::regular(),
            );
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_log_scale_puts_each_decade_at_an_equal_step_and_rejects_non_positive_values() {
        let (f, bar) = log_scale(&[1e-3, 1e-2, 1e-1, 1.0], "μ").unwrap();
        for (got, want) in f.iter().zip([0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0]) {
            assert!((got - want).abs() < 1e-12, "{f:?}");
        }
        assert_eq!((bar.bottom.as_str(), bar.top.as_str()), ("1.0e-3", "1.0e0"));
        assert_eq!(bar.unit, "μ (log)");
        // One value: the middle of the bar, not a division by zero.
        assert_eq!(log_scale(&[0.1, 0.1], "μ").unwrap().0, vec![0.5, 0.5]);
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = log_scale(&[0.1, bad], "μ").unwrap_err().to_string();
            assert!(e.contains("positive, finite"), "{e}");
        }
    }

    #[test]
    fn error_colours_run_from_the_bottom_to_the_top_of_the_bar() {
        let c = error_colors(&[0.0, 0.002, 0.004, 0.008], 0.004);
        assert_eq!(c[0], bar_colors(&[0.0])[0]);
        assert_eq!(c[1], bar_colors(&[0.5])[0]);
        // Beyond the scale: clamped to the top.
        assert_eq!(c[2], c[3]);
        assert_ne!(c[0], c[2]);
    }
}
