//! Explicit profiles from CSV: `z_mm,x_mm` per line, in the order the tool runs, z strictly
//! increasing or strictly decreasing. A first line that is not numbers is a header; blank
//! lines and lines starting with `#` are skipped.

use thiserror::Error;

use super::curve::Curve;
use super::open_spline::OpenSpline;

/// Why a profile file is refused; lines are 1-based.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ProfileError {
    #[error("{label} line {line}: {field} `{text}` is not a finite number")]
    Number {
        label: String,
        line: usize,
        field: &'static str,
        text: String,
    },
    #[error("{label} line {line}: expected two fields `z_mm,x_mm`, found {found}")]
    Fields {
        label: String,
        line: usize,
        found: usize,
    },
    #[error("{label} has {count} points: at least 3 are needed")]
    TooFew { label: String, count: usize },
    #[error(
        "{label} line {line}: z = {z_mm} mm does not continue the {sense} run of z (previous {prev_mm} mm)"
    )]
    NotMonotone {
        label: String,
        line: usize,
        z_mm: f64,
        prev_mm: f64,
        sense: &'static str,
    },
}

/// The profile in `text` (named `label` in errors) as a curve.
pub fn parse_profile(text: &str, label: &str) -> Result<Curve, ProfileError> {
    let mut pts: Vec<(usize, f64, f64)> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let t = raw.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        // Numbers only, no quoting: a split keeps the line in every error (see `lift.rs`).
        let fields: Vec<&str> = t.split(',').map(str::trim).collect();
        if pts.is_empty() && fields.iter().any(|f| f.parse::<f64>().is_err()) && line == 1 {
            continue;
        }
        if fields.len() != 2 {
            return Err(ProfileError::Fields {
                label: label.to_owned(),
                line,
                found: fields.len(),
            });
        }
        let num = |field: &'static str, s: &str| match s.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(ProfileError::Number {
                label: label.to_owned(),
                line,
                field,
                text: s.to_owned(),
            }),
        };
        pts.push((line, num("z_mm", fields[0])?, num("x_mm", fields[1])?));
    }
    if pts.len() < 3 {
        return Err(ProfileError::TooFew {
            label: label.to_owned(),
            count: pts.len(),
        });
    }
    let reversed = pts[1].1 < pts[0].1;
    for w in pts.windows(2) {
        let ok = if reversed {
            w[1].1 < w[0].1
        } else {
            w[1].1 > w[0].1
        };
        if !ok {
            return Err(ProfileError::NotMonotone {
                label: label.to_owned(),
                line: w[1].0,
                z_mm: w[1].1,
                prev_mm: w[0].1,
                sense: if reversed { "decreasing" } else { "increasing" },
            });
        }
    }
    if reversed {
        pts.reverse();
    }
    let z: Vec<f64> = pts.iter().map(|p| p.1).collect();
    let x: Vec<f64> = pts.iter().map(|p| p.2).collect();
    Ok(Curve::Profile {
        spline: OpenSpline::new(&z, &x),
        reversed,
    })
}
