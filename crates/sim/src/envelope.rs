//! The ground outline: the boundary of what the real wheel leaves as its centre runs along
//! the real path, built exactly from envelope pieces, wheel arcs and corners.
//!
//! The part is what no wheel disc covers: the complement of the union over c of the discs
//! of radius R around W(c). A point of its boundary is either the characteristic point
//! p = W − R·N of a disc in the middle of a smooth stretch of the path (N the path's unit
//! outward normal), or a point of a disc standing at the end of such a stretch: moving
//! any other disc a little along the path would cover it. So the outline is a chain of
//! - **pieces**: the envelope p(c) of a smooth stretch where R·κ < 1 (κ the path's
//!   curvature); where R·κ ≥ 1 the characteristic points are covered by the neighbouring
//!   discs and the stretch contributes only through its end discs (this happens on the far
//!   side of a crankpin from a G1 table, where a polar-linear segment turns with radius
//!   ≈ d < R);
//! - **discs**: the wheel at every table point (where the path may kink) and wherever R·κ
//!   crosses 1, each contributing a concave arc of radius R, possibly of zero length;
//! - **corners** where two neighbours in the chain cross.
//!
//! Consecutive elements meet tangentially (a piece and the disc at its own end) or cross;
//! an element whose two junctions leave it nothing (a piece trimmed to nothing, a disc arc
//! that would have to be convex) is dropped and its neighbours are joined, until every
//! element is valid. For a G1 cam table this means: at a table point where the path's
//! normal turns by θ towards the part (θ > 0) the two pieces cross at a corner, each losing
//! about R·θ/2 of outline; at the nose of a lobe ground from a 1° table that is most of each
//! piece, so it is not a negligible correction. Where θ < 0 the wheel at the table point
//! grinds a concave arc. |θ| ≤ [`SMOOTH_KINK_RAD`] is left as it is: trimming or filling
//! would move the outline by at most R·θ²/8 ≈ 3e-11 mm for R = 250 mm.
//!
//! Only neighbours in the chain are intersected; that is exact while no element is cut by
//! one further away than its current neighbour, which holds for the convex parts a wheel
//! can grind (a piece loses R·θ/2 at each end out of about (d − R)·Δc).

use super::SimError;
use super::path::{MachinePath, add, angle, cross, dot, norm, scale, sub};
use super::table::wrap_pi;

/// Normal jumps up to this (radians) at a table point count as smooth.
pub(crate) const SMOOTH_KINK_RAD: f64 = 1e-6;
/// Spacing of the outline nodes placed on a corner or a wheel arc, radians (0.25°).
const ARC_NODE_STEP_RAD: f64 = 0.25 * std::f64::consts::PI / 180.0;
/// Newton iterations allowed for one crossing (quadratic convergence from a close first
/// guess takes three to five).
const NEWTON_ITERATIONS: usize = 60;
/// Two pieces count as meeting when their points are this close, mm.
const CORNER_MATCH_MM: f64 = 1e-10;

/// One outline node: a point of the part's boundary and its unit outward normal there
/// (at a corner, one of the normals of its normal cone).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Node {
    pub p: [f64; 2],
    pub n: [f64; 2],
}

/// A candidate element of the outline chain.
#[derive(Debug, Clone, Copy)]
enum Elem {
    /// The regular envelope of table segment `seg` over c ∈ [lo, hi] (radians), with the
    /// element indices of the discs standing at its two ends.
    Piece {
        seg: usize,
        lo: f64,
        hi: f64,
        start_disc: usize,
        end_disc: usize,
    },
    /// The wheel standing at `centre`; its boundary points are centre − R·u(ψ), ψ the
    /// outward normal angle.
    Disc { centre: [f64; 2], c: f64 },
}

/// A convex corner: the outline's normal turns by `span` ≥ 0 at `point`.
#[derive(Debug, Clone, Copy)]
struct Corner {
    point: [f64; 2],
    psi_from: f64,
    span: f64,
}

/// Where an element ends and the next begins (a piece's c, a disc's normal angle ψ).
#[derive(Debug, Clone, Copy)]
struct Junction {
    prev_end: f64,
    next_start: f64,
    corner: Option<Corner>,
}

enum Link {
    Joined(Junction),
    /// The element before (`true`) or after (`false`) lies wholly under the other.
    Swallowed {
        prev: bool,
    },
}

/// The ground outline as nodes in boundary order (counter-clockwise, not closed: the last
/// node is followed by the first).
pub(crate) fn outline(
    path: &MachinePath,
    samples_per_segment: usize,
) -> Result<Vec<Node>, SimError> {
    let elems = elements(path, samples_per_segment);
    let mut chain = Chain::new(elems.len());
    // Junctions to (re)compute, then elements to (re)check, until nothing changes.
    let mut dirty: Vec<usize> = (0..elems.len()).rev().collect();
    let mut check: Vec<usize> = Vec::new();
    while !dirty.is_empty() {
        while let Some(i) = dirty.pop() {
            if !chain.alive[i] {
                continue;
            }
            let j = chain.next[i];
            match link(path, &elems, i, j)? {
                Link::Joined(junction) => {
                    chain.out[i] = Some(junction);
                    check.push(i);
                    check.push(j);
                }
                Link::Swallowed { prev: true } => dirty.push(chain.remove(&elems, i)?),
                Link::Swallowed { prev: false } => {
                    chain.remove(&elems, j)?;
                    dirty.push(i);
                }
            }
        }
        while let Some(i) = check.pop() {
            if !chain.alive[i] {
                continue;
            }
            let (Some(inbound), Some(outbound)) = (chain.out[chain.prev[i]], chain.out[i]) else {
                continue;
            };
            if !valid(&elems[i], &inbound, &outbound) {
                dirty.push(chain.remove(&elems, i)?);
            }
        }
    }
    emit(path, &elems, &chain, samples_per_segment)
}

/// The outline chain as a cyclic doubly linked list over the candidate elements.
struct Chain {
    next: Vec<usize>,
    prev: Vec<usize>,
    alive: Vec<bool>,
    alive_count: usize,
    /// The junction between element i and next[i], once computed.
    out: Vec<Option<Junction>>,
}

impl Chain {
    fn new(m: usize) -> Self {
        Self {
            next: (0..m).map(|i| (i + 1) % m).collect(),
            prev: (0..m).map(|i| (i + m - 1) % m).collect(),
            alive: vec![true; m],
            alive_count: m,
            out: vec![None; m],
        }
    }

    /// Drops element `i`; returns its predecessor, whose junction must be recomputed.
    fn remove(&mut self, elems: &[Elem], i: usize) -> Result<usize, SimError> {
        self.alive[i] = false;
        self.alive_count -= 1;
        let (p, q) = (self.prev[i], self.next[i]);
        self.next[p] = q;
        self.prev[q] = p;
        self.out[p] = None;
        self.out[i] = None;
        if self.alive_count < 3 {
            return Err(SimError::OutlineNotResolved {
                c_deg: element_c_deg(&elems[i]),
            });
        }
        Ok(p)
    }
}

/// The candidate chain: for each table segment, the disc at its start, then its regular
/// stretches (R·κ < 1), with a disc wherever R·κ crosses 1.
fn elements(path: &MachinePath, samples: usize) -> Vec<Elem> {
    let r = path.wheel_radius_mm;
    let mut elems = Vec::with_capacity(path.table.len() * 2);
    for k in 0..path.table.len() {
        let (s, e) = path.range(k);
        elems.push(Elem::Disc {
            centre: path.at(k, s).w,
            c: s,
        });
        let tight = |c: f64| r * path.at(k, c).kappa >= 1.0;
        let cs: Vec<f64> = (0..=samples)
            .map(|j| s + (e - s) * j as f64 / samples as f64)
            .collect();
        let flags: Vec<bool> = cs.iter().map(|&c| tight(c)).collect();
        let mut start = (!flags[0]).then_some((s, elems.len() - 1));
        for j in 1..=samples {
            if flags[j] == flags[j - 1] {
                continue;
            }
            let c_star = bisect(&tight, cs[j - 1], cs[j], flags[j - 1]);
            if let Some((lo, start_disc)) = start.take() {
                elems.push(Elem::Piece {
                    seg: k,
                    lo,
                    hi: c_star,
                    start_disc,
                    end_disc: elems.len() + 1,
                });
            }
            elems.push(Elem::Disc {
                centre: path.at(k, c_star).w,
                c: c_star,
            });
            if !flags[j] {
                start = Some((c_star, elems.len() - 1));
            }
        }
        if let Some((lo, start_disc)) = start {
            elems.push(Elem::Piece {
                seg: k,
                lo,
                hi: e,
                start_disc,
                end_disc: elems.len() + 1,
            });
        }
    }
    // The last piece ends at the first disc.
    let m = elems.len();
    if let Some(Elem::Piece { end_disc, .. }) = elems.last_mut()
        && *end_disc == m
    {
        *end_disc = 0;
    }
    elems
}

/// The point in [a, b] where `pred` switches from `at_a` to the other value, to 1e-14 rad.
fn bisect(pred: &impl Fn(f64) -> bool, mut a: f64, mut b: f64, at_a: bool) -> f64 {
    while b - a > 1e-14 {
        let mid = 0.5 * (a + b);
        if mid <= a || mid >= b {
            break;
        }
        if pred(mid) == at_a {
            a = mid;
        } else {
            b = mid;
        }
    }
    0.5 * (a + b)
}

/// How elements `i` and `j` (its successor in the chain) meet.
fn link(path: &MachinePath, elems: &[Elem], i: usize, j: usize) -> Result<Link, SimError> {
    match (elems[i], elems[j]) {
        (
            Elem::Piece {
                seg, hi, end_disc, ..
            },
            Elem::Disc { .. },
        ) if end_disc == j => {
            let n = path.at(seg, hi).n;
            Ok(Link::Joined(Junction {
                prev_end: hi,
                next_start: angle(n),
                corner: None,
            }))
        }
        (
            Elem::Disc { .. },
            Elem::Piece {
                seg,
                lo,
                start_disc,
                ..
            },
        ) if start_disc == i => {
            let n = path.at(seg, lo).n;
            Ok(Link::Joined(Junction {
                prev_end: angle(n),
                next_start: lo,
                corner: None,
            }))
        }
        (piece @ Elem::Piece { .. }, Elem::Disc { centre, c }) => {
            piece_disc(path, &piece, centre, true).ok_or(SimError::OutlineNotResolved {
                c_deg: c.to_degrees().rem_euclid(360.0),
            })
        }
        (Elem::Disc { centre, c }, piece @ Elem::Piece { .. }) => {
            piece_disc(path, &piece, centre, false).ok_or(SimError::OutlineNotResolved {
                c_deg: c.to_degrees().rem_euclid(360.0),
            })
        }
        (Elem::Disc { centre: w1, c }, Elem::Disc { centre: w2, .. }) => {
            disc_disc(w1, w2, path.wheel_radius_mm).ok_or(SimError::OutlineNotResolved {
                c_deg: c.to_degrees().rem_euclid(360.0),
            })
        }
        (a @ Elem::Piece { .. }, b @ Elem::Piece { .. }) => {
            piece_piece(path, &a, &b).ok_or(SimError::OutlineNotResolved {
                c_deg: element_c_deg(&b),
            })
        }
    }
}

/// Where a piece (before the disc when `piece_first`, after it otherwise) crosses the
/// circle of radius R around `centre`: Newton on f(c) = |p(c) − centre|² − R², kept inside
/// the bracket given by the sign change. `None` when the piece does not cross it.
fn piece_disc(
    path: &MachinePath,
    piece: &Elem,
    centre: [f64; 2],
    piece_first: bool,
) -> Option<Link> {
    let Elem::Piece { seg, lo, hi, .. } = *piece else {
        return None;
    };
    let r = path.wheel_radius_mm;
    let f = |c: f64| {
        let s = path.at(seg, c);
        let v = sub(s.p, centre);
        (dot(v, v) - r * r, 2.0 * dot(v, s.dp))
    };
    let (f_lo, f_hi) = (f(lo).0, f(hi).0);
    // Outside the disc f > 0: the piece before it runs in, the piece after it runs out.
    let (inside_end, outside_end) = if piece_first {
        (f_hi, f_lo)
    } else {
        (f_lo, f_hi)
    };
    if outside_end <= 0.0 {
        return Some(Link::Swallowed { prev: piece_first });
    }
    if inside_end >= 0.0 {
        return None;
    }
    let (mut a, mut b) = (lo, hi);
    let mut c = 0.5 * (a + b);
    for _ in 0..NEWTON_ITERATIONS {
        let (v, dv) = f(c);
        // Keep [a, b] bracketing the sign change.
        if (v > 0.0) == (f_lo > 0.0) {
            a = c;
        } else {
            b = c;
        }
        let step = v / dv;
        let newton = c - step;
        c = if dv != 0.0 && newton > a && newton < b {
            newton
        } else {
            0.5 * (a + b)
        };
        if step.abs() < 1e-15 || b - a < 1e-15 {
            break;
        }
    }
    let s = path.at(seg, c);
    let psi_piece = angle(s.n);
    let psi_disc = angle(sub(centre, s.p));
    Some(Link::Joined(if piece_first {
        Junction {
            prev_end: c,
            next_start: psi_disc,
            corner: Some(Corner {
                point: s.p,
                psi_from: psi_piece,
                span: wrap_pi(psi_disc - psi_piece),
            }),
        }
    } else {
        Junction {
            prev_end: psi_disc,
            next_start: c,
            corner: Some(Corner {
                point: s.p,
                psi_from: psi_disc,
                span: wrap_pi(psi_piece - psi_disc),
            }),
        }
    }))
}

/// Where the circles of radius R around `w1` and then `w2` cross on the part's side (the
/// left of the path's direction of travel). `None` when they do not cross.
fn disc_disc(w1: [f64; 2], w2: [f64; 2], r: f64) -> Option<Link> {
    let d = sub(w2, w1);
    let len = norm(d);
    if len < 1e-12 {
        return Some(Link::Swallowed { prev: false });
    }
    let half = 0.5 * len;
    if half >= r {
        return None;
    }
    let left = [-d[1] / len, d[0] / len];
    let x = add(
        add(w1, scale(d, 0.5)),
        scale(left, (r * r - half * half).sqrt()),
    );
    let (psi1, psi2) = (angle(sub(w1, x)), angle(sub(w2, x)));
    Some(Link::Joined(Junction {
        prev_end: psi1,
        next_start: psi2,
        corner: Some(Corner {
            point: x,
            psi_from: psi1,
            span: wrap_pi(psi2 - psi1),
        }),
    }))
}

/// Where piece `a` and the following piece `b` cross: Newton on pA(ca) = pB(cb) from a
/// first guess that trims each by R·θ/2 of outline (θ the normal turn between their ends).
fn piece_piece(path: &MachinePath, a: &Elem, b: &Elem) -> Option<Link> {
    let (
        Elem::Piece {
            seg: ia,
            lo: a_lo,
            hi: a_hi,
            ..
        },
        Elem::Piece {
            seg: ib,
            lo: b_lo,
            hi: b_hi,
            ..
        },
    ) = (*a, *b)
    else {
        return None;
    };
    let (sa, sb) = (path.at(ia, a_hi), path.at(ib, b_lo));
    let theta = wrap_pi(angle(sb.n) - angle(sa.n)).max(SMOOTH_KINK_RAD);
    let half = 0.5 * path.wheel_radius_mm * theta;
    let mut ca = a_hi - half / norm(sa.dp);
    let mut cb = b_lo + half / norm(sb.dp);
    for _ in 0..NEWTON_ITERATIONS {
        let (pa, pb) = (path.at(ia, ca), path.at(ib, cb));
        let rhs = sub(pb.p, pa.p);
        if norm(rhs) <= CORNER_MATCH_MM {
            if ca <= a_lo {
                return Some(Link::Swallowed { prev: true });
            }
            if cb >= b_hi {
                return Some(Link::Swallowed { prev: false });
            }
            let psi_from = angle(pa.n);
            return Some(Link::Joined(Junction {
                prev_end: ca,
                next_start: cb,
                corner: Some(Corner {
                    point: scale(add(pa.p, pb.p), 0.5),
                    psi_from,
                    span: wrap_pi(angle(pb.n) - psi_from),
                }),
            }));
        }
        // Solve pa.dp·Δa − pb.dp·Δb = pb.p − pa.p by Cramer's rule.
        let col_b = scale(pb.dp, -1.0);
        let det = cross(pa.dp, col_b);
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        ca += cross(rhs, col_b) / det;
        cb += cross(pa.dp, rhs) / det;
    }
    None
}

/// An element keeps something between its two junctions: a piece a stretch of c, a disc
/// a concave arc (its normal turning back, or not turning more than a smooth joint does).
fn valid(elem: &Elem, inbound: &Junction, outbound: &Junction) -> bool {
    match elem {
        Elem::Piece { .. } => outbound.prev_end > inbound.next_start,
        Elem::Disc { .. } => wrap_pi(outbound.prev_end - inbound.next_start) <= SMOOTH_KINK_RAD,
    }
}

/// Nodes along the resolved chain.
fn emit(
    path: &MachinePath,
    elems: &[Elem],
    chain: &Chain,
    samples: usize,
) -> Result<Vec<Node>, SimError> {
    let (next, out) = (&chain.next, &chain.out);
    let first = (0..elems.len())
        .find(|&i| chain.alive[i])
        .ok_or(SimError::OutlineNotResolved { c_deg: 0.0 })?;
    let mut nodes = Vec::with_capacity(elems.len() * (samples + 4));
    let mut previous = first;
    let mut i = next[first];
    loop {
        let (Some(inbound), Some(outbound)) = (out[previous], out[i]) else {
            return Err(SimError::OutlineNotResolved {
                c_deg: element_c_deg(&elems[i]),
            });
        };
        match elems[i] {
            Elem::Disc { centre, .. } => {
                let span = wrap_pi(outbound.prev_end - inbound.next_start);
                let r = path.wheel_radius_mm;
                push_fan(&mut nodes, inbound.next_start, span, |n| {
                    sub(centre, scale(n, r))
                });
            }
            Elem::Piece { seg, .. } => {
                let (start, end) = (inbound.next_start, outbound.prev_end);
                for j in 0..=samples {
                    let s = path.at(seg, start + (end - start) * j as f64 / samples as f64);
                    nodes.push(Node { p: s.p, n: s.n });
                }
            }
        }
        if let Some(corner) = outbound.corner {
            if corner.span < -SMOOTH_KINK_RAD {
                return Err(SimError::OutlineNotResolved {
                    c_deg: element_c_deg(&elems[i]),
                });
            }
            push_fan(&mut nodes, corner.psi_from, corner.span, |_| corner.point);
        }
        if i == first {
            break;
        }
        previous = i;
        i = next[i];
    }
    Ok(nodes)
}

/// Nodes on a fan of normals from `psi_from` turning by `span`, endpoints included, with
/// the point for each normal given by `point`.
fn push_fan(nodes: &mut Vec<Node>, psi_from: f64, span: f64, point: impl Fn([f64; 2]) -> [f64; 2]) {
    let steps = ((span.abs() / ARC_NODE_STEP_RAD).ceil() as usize).max(1);
    for j in 0..=steps {
        let (sin, cos) = (psi_from + span * j as f64 / steps as f64).sin_cos();
        let n = [cos, sin];
        nodes.push(Node { p: point(n), n });
    }
}

/// A C angle (degrees, 0..360) to name an element in an error.
fn element_c_deg(elem: &Elem) -> f64 {
    let c = match *elem {
        Elem::Piece { lo, hi, .. } => 0.5 * (lo + hi),
        Elem::Disc { c, .. } => c,
    };
    c.to_degrees().rem_euclid(360.0)
}
