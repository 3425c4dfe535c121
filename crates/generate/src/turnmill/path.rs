//! Paths of the turn-mill features in the part frame: chains of lines and arcs, offset
//! towards the tool side (remaining stock, and the tool radius when it is baked in), and
//! turned into the machine frame by C.
//!
//! Offsetting keeps tangent joins joined; a corner the tool goes round on its outside gets
//! an arc about the corner of the offset's radius, and a corner the tool would have to cut
//! into (the offset curves overlap) is refused, naming the segment: closing such a corner
//! needs intersections that a drawing of tangent arcs and lines does not have.

use std::f64::consts::PI;

/// A point (x, y), mm.
pub type P = (f64, f64);

/// Side of the tool, looking along the direction of travel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    Left,
    Right,
}

/// One element of a path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Seg {
    Line {
        from: P,
        to: P,
    },
    /// `sweep_deg` > 0 counter-clockwise.
    Arc {
        centre: P,
        radius: f64,
        start_deg: f64,
        sweep_deg: f64,
    },
}

fn polar(c: P, r: f64, deg: f64) -> P {
    let (s, co) = deg.to_radians().sin_cos();
    (c.0 + r * co, c.1 + r * s)
}

fn unit(v: P) -> P {
    let l = v.0.hypot(v.1);
    (v.0 / l, v.1 / l)
}

impl Seg {
    pub fn start(&self) -> P {
        match *self {
            Seg::Line { from, .. } => from,
            Seg::Arc {
                centre,
                radius,
                start_deg,
                ..
            } => polar(centre, radius, start_deg),
        }
    }
    pub fn end(&self) -> P {
        match *self {
            Seg::Line { to, .. } => to,
            Seg::Arc {
                centre,
                radius,
                start_deg,
                sweep_deg,
            } => polar(centre, radius, start_deg + sweep_deg),
        }
    }
    /// Unit tangent along travel at the start (`at_end` false) or the end.
    pub fn tangent(&self, at_end: bool) -> P {
        match *self {
            Seg::Line { from, to } => unit((to.0 - from.0, to.1 - from.1)),
            Seg::Arc {
                start_deg,
                sweep_deg,
                ..
            } => {
                let a = if at_end {
                    start_deg + sweep_deg
                } else {
                    start_deg
                }
                .to_radians();
                let s = sweep_deg.signum();
                (-a.sin() * s, a.cos() * s)
            }
        }
    }
    /// The element `d` mm towards `side`; `None` when an arc's radius would vanish.
    fn offset(&self, side: Side, d: f64) -> Option<Seg> {
        match *self {
            Seg::Line { from, to } => {
                let n = normal(self.tangent(false), side);
                Some(Seg::Line {
                    from: (from.0 + d * n.0, from.1 + d * n.1),
                    to: (to.0 + d * n.0, to.1 + d * n.1),
                })
            }
            Seg::Arc {
                centre,
                radius,
                start_deg,
                sweep_deg,
            } => {
                // Left of a counter-clockwise arc is its centre.
                let inward = (side == Side::Left) == (sweep_deg > 0.0);
                let r = if inward { radius - d } else { radius + d };
                (r > 0.0).then_some(Seg::Arc {
                    centre,
                    radius: r,
                    start_deg,
                    sweep_deg,
                })
            }
        }
    }
    /// The element in the machine frame with C at `c_deg`: turned by −C.
    pub fn to_machine(&self, c_deg: f64) -> Seg {
        match *self {
            Seg::Line { from, to } => Seg::Line {
                from: machine(from, c_deg),
                to: machine(to, c_deg),
            },
            Seg::Arc {
                centre,
                radius,
                start_deg,
                sweep_deg,
            } => Seg::Arc {
                centre: machine(centre, c_deg),
                radius,
                start_deg: start_deg - c_deg,
                sweep_deg,
            },
        }
    }
}

/// Unit normal to tangent `t` on `side`.
pub fn normal(t: P, side: Side) -> P {
    match side {
        Side::Left => (-t.1, t.0),
        Side::Right => (t.1, -t.0),
    }
}

/// Part frame to machine frame with C at `c_deg`: `X = cos C·a + sin C·b`,
/// `Y = −sin C·a + cos C·b`.
pub fn machine(p: P, c_deg: f64) -> P {
    let (s, c) = c_deg.to_radians().sin_cos();
    (c * p.0 + s * p.1, -s * p.0 + c * p.1)
}

/// Why a path cannot be offset; `segment` is 1-based.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OffsetError {
    /// The arc's radius is not larger than the offset.
    ArcTooSmall { segment: usize },
    /// The corner after the segment would need the tool to cut into the part.
    InsideCorner { segment: usize },
}

/// `path` offset by `d` towards `side`, with arcs round outside corners.
pub fn offset(path: &[Seg], side: Side, d: f64) -> Result<Vec<Seg>, OffsetError> {
    let mut out: Vec<Seg> = Vec::with_capacity(path.len());
    for (i, s) in path.iter().enumerate() {
        let o = s
            .offset(side, d)
            .ok_or(OffsetError::ArcTooSmall { segment: i + 1 })?;
        if let Some(prev) = path.get(i.wrapping_sub(1)).filter(|_| i > 0) {
            let (t0, t1) = (prev.tangent(true), s.tangent(false));
            let cross = t0.0 * t1.1 - t0.1 * t1.0;
            let dot = t0.0 * t1.0 + t0.1 * t1.1;
            // Joins tangent to 1e-6 rad (the drawing's own precision) stay joined.
            if d > 0.0 && (cross.abs() > 1e-6 || dot < 0.0) {
                let turns_left = cross > 0.0;
                if turns_left == (side == Side::Left) {
                    return Err(OffsetError::InsideCorner { segment: i });
                }
                let a0 = normal(t0, side);
                let a1 = normal(t1, side);
                let start = a0.1.atan2(a0.0).to_degrees();
                let turn = a1.1.atan2(a1.0).to_degrees() - start;
                // The arc turns the way the path turns, less than half a turn.
                let sweep = if turns_left {
                    turn.rem_euclid(360.0)
                } else {
                    -(-turn).rem_euclid(360.0)
                };
                out.push(Seg::Arc {
                    centre: prev.end(),
                    radius: d,
                    start_deg: start,
                    sweep_deg: sweep,
                });
            }
        }
        out.push(o);
    }
    Ok(out)
}

/// Arcs split into pieces of at most 180°, so each G2/G3 block is unambiguous on every
/// control; lines unchanged.
pub fn split_arcs(path: &[Seg]) -> Vec<Seg> {
    let mut out = Vec::new();
    for s in path {
        match *s {
            Seg::Arc {
                centre,
                radius,
                start_deg,
                sweep_deg,
            } => {
                let pieces = (sweep_deg.abs() / 180.0).ceil().max(1.0) as usize;
                for k in 0..pieces {
                    let step = sweep_deg / pieces as f64;
                    out.push(Seg::Arc {
                        centre,
                        radius,
                        start_deg: start_deg + step * k as f64,
                        sweep_deg: step,
                    });
                }
            }
            line => out.push(line),
        }
    }
    out
}

/// Farthest distance of the path from the part's axis, mm.
pub fn reach(path: &[Seg]) -> f64 {
    path.iter()
        .map(|s| match *s {
            Seg::Line { from, to } => from.0.hypot(from.1).max(to.0.hypot(to.1)),
            Seg::Arc { centre, radius, .. } => centre.0.hypot(centre.1) + radius,
        })
        .fold(0.0, f64::max)
}

/// Sweep of an arc from `from` to `to` about `centre`, degrees: (0, 360] counter-clockwise,
/// [−360, 0) clockwise; the same point gives a full turn.
pub fn sweep_between(centre: P, from: P, to: P, ccw: bool) -> f64 {
    let a0 = (from.1 - centre.1).atan2(from.0 - centre.0);
    let a1 = (to.1 - centre.1).atan2(to.0 - centre.0);
    let d = if ccw { a1 - a0 } else { a0 - a1 }.rem_euclid(2.0 * PI);
    let d = if d < 1e-12 { 2.0 * PI } else { d };
    if ccw { d.to_degrees() } else { -d.to_degrees() }
}

/// The point at `r` and `deg` about the part's axis.
pub fn polar_deg(r: f64, deg: f64) -> P {
    polar((0.0, 0.0), r, deg)
}

/// Distance from `p` to the element.
pub fn distance(s: &Seg, p: P) -> f64 {
    match *s {
        Seg::Line { from, to } => {
            let (dx, dy) = (to.0 - from.0, to.1 - from.1);
            let len2 = dx * dx + dy * dy;
            let t = (((p.0 - from.0) * dx + (p.1 - from.1) * dy) / len2).clamp(0.0, 1.0);
            (p.0 - from.0 - t * dx).hypot(p.1 - from.1 - t * dy)
        }
        Seg::Arc {
            centre,
            radius,
            start_deg,
            sweep_deg,
        } => {
            let a = (p.1 - centre.1).atan2(p.0 - centre.0).to_degrees();
            let into = if sweep_deg > 0.0 {
                (a - start_deg).rem_euclid(360.0)
            } else {
                (start_deg - a).rem_euclid(360.0)
            };
            if sweep_deg.abs() >= 360.0 || into <= sweep_deg.abs() {
                ((p.0 - centre.0).hypot(p.1 - centre.1) - radius).abs()
            } else {
                let (a, b) = (s.start(), s.end());
                (p.0 - a.0)
                    .hypot(p.1 - a.1)
                    .min((p.0 - b.0).hypot(p.1 - b.1))
            }
        }
    }
}
