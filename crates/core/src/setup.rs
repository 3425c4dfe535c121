//! What the setup picture shows, computed from a part: outline, wheel-centre path, and the
//! wheel touching the part at chosen table angles.

use super::geometry::{GeometryError, Part};
use super::svg::{SetupCircle, SetupView, WheelPosition};

/// Outline and path samples per revolution: smooth at any zoom the picture offers.
const SAMPLES: usize = 1440;

/// The setup of `part` with the wheel drawn at each of `angles_deg` (table angles).
pub fn setup_view(
    part: &Part,
    angles_deg: &[f64],
    title: &str,
) -> Result<SetupView, GeometryError> {
    let pair = |p: [f64; 2]| (p[0], p[1]);
    let path = part.wheel_table(SAMPLES)?;
    let wheel_centre_path_mm = path
        .iter()
        .map(|p| {
            let (s, c) = p.c_deg.to_radians().sin_cos();
            (p.d_mm * c, p.d_mm * s)
        })
        .collect();
    let wheels = angles_deg
        .iter()
        .map(|&c_deg| {
            let (centre, contact) = part.contact_at_c_deg(c_deg)?;
            Ok(WheelPosition {
                centre_mm: pair(centre),
                radius_mm: part.wheel_radius_mm(),
                label: format!("c = {c_deg}°"),
                contact_mm: Some(pair(contact)),
            })
        })
        .collect::<Result<_, GeometryError>>()?;
    let circles = part
        .reference_circle()
        .map(|(centre, radius_mm, label)| SetupCircle {
            centre_mm: pair(centre),
            radius_mm,
            label,
            dashed: true,
        })
        .into_iter()
        .collect();
    Ok(SetupView {
        title: title.to_string(),
        part_outline_mm: part.outline(SAMPLES).into_iter().map(pair).collect(),
        circles,
        wheel_centre_path_mm,
        wheels,
    })
}
