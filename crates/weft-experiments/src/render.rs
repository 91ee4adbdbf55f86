//! Software rendering of a triangle mesh coloured by per-vertex error: an orthographic
//! view, faces painted back to front (painter's algorithm), each face's colour the
//! viridis colour of its mean vertex error shaded by how squarely it faces the camera,
//! and a colour bar in millimetres.

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
    errors
        .iter()
        .map(|&e| {
            let c = ViridisRGB.get_color_normalized((e / scale.max(1e-300)).clamp(0.0, 1.0), 0.0, 1.0);
            [c.0, c.1, c.2]
        })
        .collect()
}

/// Renders `positions` (flat, m) with `faces`, coloured by `errors` (m per vertex) on a
/// scale from 0 to `scale` (m), to a PNG at `path`.
pub fn error_png(
    path: &Path,
    positions: &[f64],
    faces: &[[usize; 3]],
    errors: &[f64],
    scale: f64,
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
        let e = t.iter().map(|&v| errors[v]).sum::<f64>() / 3.0;
        let c = ViridisRGB.get_color_normalized((e / scale).clamp(0.0, 1.0), 0.0, 1.0);
        let shade = 0.45 + 0.55 * facing;
        let rgb = RGBColor(
            (c.0 as f64 * shade) as u8,
            (c.1 as f64 * shade) as u8,
            (c.2 as f64 * shade) as u8,
        );
        let pts: Vec<(i32, i32)> = t.iter().map(|&v| to_px(screen[v])).collect();
        root.draw(&Polygon::new(pts, rgb.filled()))?;
    }
    // Colour bar with its scale in millimetres.
    let (bx, by, bh) = (WIDTH as i32 - BAR + 10, 50, HEIGHT as i32 - 100);
    for k in 0..bh {
        let c = ViridisRGB.get_color_normalized(1.0 - k as f64 / bh as f64, 0.0, 1.0);
        root.draw(&Rectangle::new([(bx, by + k), (bx + 14, by + k + 1)], c.filled()))?;
    }
    let label = |v: f64| format!("{:.3}", 1e3 * v);
    root.draw(&Text::new(
        label(scale),
        (bx + 17, by - 5),
        ("sans-serif", 12).into_font(),
    ))?;
    root.draw(&Text::new(
        label(0.0),
        (bx + 17, by + bh - 8),
        ("sans-serif", 12).into_font(),
    ))?;
    root.draw(&Text::new(
        "mm".to_string(),
        (bx, by + bh + 10),
        ("sans-serif", 12).into_font(),
    ))?;
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
