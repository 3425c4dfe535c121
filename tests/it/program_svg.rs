//! SVG of the setup: golden file of a small view, XML well-formedness and structure of a
//! realistic cam setup, fitting of both panels, robustness to bad input.

use camloop::core::svg::{SetupCircle, SetupView, WheelPosition, render_setup_svg};

const RB_MM: f64 = 20.0;
const R_WHEEL_MM: f64 = 300.0;

/// Lift of a test cam, mm: 8 mm of 1 − cos over 180°, nose at ψ = 90°; returns (h, h').
/// Radius of curvature Rb + h + h'' stays ≥ 12 mm, so the flat-follower geometry is valid.
fn lift(psi: f64) -> (f64, f64) {
    let t = psi - std::f64::consts::FRAC_PI_2;
    if t.abs() < std::f64::consts::FRAC_PI_2 {
        (4.0 * (1.0 + (2.0 * t).cos()), -8.0 * (2.0 * t).sin())
    } else {
        (0.0, 0.0)
    }
}

/// Flat-follower geometry (domain notes): profile point p = (Rb + h)·u + h'·u⊥ touched at
/// ψ, wheel centre p + R·u. Returns (p, wheel centre, c in degrees).
fn contact(psi_deg: f64) -> ((f64, f64), (f64, f64), f64) {
    let psi = psi_deg.to_radians();
    let (h, dh) = lift(psi);
    let (u, up) = ((psi.cos(), psi.sin()), (-psi.sin(), psi.cos()));
    let p = ((RB_MM + h) * u.0 + dh * up.0, (RB_MM + h) * u.1 + dh * up.1);
    let c = (p.0 + R_WHEEL_MM * u.0, p.1 + R_WHEEL_MM * u.1);
    (p, c, c.1.atan2(c.0).to_degrees())
}

fn cam_view() -> SetupView {
    let outline = (0..360).map(|i| contact(f64::from(i)).0).collect();
    let path = (0..360).map(|i| contact(f64::from(i)).1).collect();
    let wheels = [0.0, 60.0, 90.0, 150.0]
        .into_iter()
        .map(|psi| {
            let (p, centre, c_deg) = contact(psi);
            WheelPosition {
                centre_mm: centre,
                radius_mm: R_WHEEL_MM,
                label: format!("c = {c_deg:.1}°"),
                contact_mm: Some(p),
            }
        })
        .collect();
    SetupView {
        title: "Test cam, Rb 20 mm, lift 8 mm, wheel R 300 mm".to_owned(),
        part_outline_mm: outline,
        circles: vec![SetupCircle {
            centre_mm: (0.0, 0.0),
            radius_mm: RB_MM,
            label: "base circle".to_owned(),
            dashed: true,
        }],
        wheel_centre_path_mm: path,
        wheels,
    }
}

#[test]
fn small_view_golden() {
    let view = SetupView {
        title: "Pin & wheel <small>".to_owned(),
        part_outline_mm: vec![(10.0, -10.0), (30.0, -10.0), (30.0, 10.0), (10.0, 10.0)],
        circles: vec![SetupCircle {
            centre_mm: (20.0, 0.0),
            radius_mm: 10.0,
            label: "pin".to_owned(),
            dashed: false,
        }],
        wheel_centre_path_mm: vec![(250.0, 0.0), (0.0, 250.0), (-250.0, 0.0), (0.0, -250.0)],
        wheels: vec![WheelPosition {
            centre_mm: (250.0, 0.0),
            radius_mm: 220.0,
            label: "c = 0°".to_owned(),
            contact_mm: Some((30.0, 0.0)),
        }],
    };
    insta::assert_snapshot!(render_setup_svg(&view));
}

fn view_box(node: roxmltree::Node<'_, '_>) -> [f64; 4] {
    let v: Vec<f64> = node
        .attribute("viewBox")
        .unwrap()
        .split_whitespace()
        .map(|t| t.parse().unwrap())
        .collect();
    [v[0], v[1], v[2], v[3]]
}

/// Is (x, y) in the part frame inside a panel's viewBox (which holds (x, −y))?
fn inside(vb: [f64; 4], (x, y): (f64, f64)) -> bool {
    let (vx, vy, vw, vh) = (vb[0], vb[1], vb[2], vb[3]);
    vx <= x && x <= vx + vw && vy <= -y && -y <= vy + vh
}

#[test]
fn cam_setup_is_well_formed_and_shows_everything() {
    let view = cam_view();
    let svg = render_setup_svg(&view);
    let doc = roxmltree::Document::parse(&svg).unwrap();
    let count = |class: &str| {
        doc.descendants()
            .filter(|n| n.attribute("class") == Some(class))
            .count()
    };
    // Each wheel is drawn in both panels.
    assert_eq!(count("wheel"), 2 * view.wheels.len());
    assert_eq!(count("contact"), 2 * view.wheels.len());
    assert_eq!(count("part"), 2);
    assert_eq!(count("rotation-centre"), 2);
    assert_eq!(count("scale-bar"), 2);
    assert_eq!(count("zoom-window"), 1);

    let panel = |id: &str| {
        doc.descendants()
            .find(|n| n.has_tag_name("svg") && n.attribute("id") == Some(id))
            .unwrap()
    };
    let (overview, zoom) = (view_box(panel("overview")), view_box(panel("zoom")));
    // The overview holds every full wheel; the zoom holds the part and the contact points
    // but is far smaller than a wheel, so only arcs of the wheels show there.
    for wh in &view.wheels {
        let (cx, cy) = wh.centre_mm;
        for corner in [(cx - 300.0, cy - 300.0), (cx + 300.0, cy + 300.0)] {
            assert!(
                inside(overview, corner),
                "{corner:?} outside the overview {overview:?}"
            );
        }
        assert!(inside(zoom, wh.contact_mm.unwrap()));
        assert!(!inside(zoom, wh.centre_mm));
    }
    for p in &view.part_outline_mm {
        assert!(inside(zoom, *p));
    }
    assert!(
        zoom[2] < 100.0 && zoom[2] > 56.0,
        "zoom window {zoom:?} mm for a 56 mm cam"
    );

    // Text is never inside the mirroring group.
    for text in doc.descendants().filter(|n| n.has_tag_name("text")) {
        assert!(
            !text
                .ancestors()
                .any(|a| a.attribute("transform") == Some("scale(1,-1)")),
            "mirrored text: {:?}",
            text.text()
        );
    }
    // The wheel labels appear in both panels.
    let labels: Vec<&str> = doc
        .descendants()
        .filter(|n| n.attribute("class") == Some("wheel-label"))
        .filter_map(|n| n.text())
        .collect();
    assert_eq!(labels.len(), 2 * view.wheels.len());
    assert!(labels.contains(&"c = 0.0°"), "{labels:?}");
}

#[test]
fn bad_values_are_skipped_and_counted() {
    let mut view = cam_view();
    view.part_outline_mm.push((f64::NAN, 0.0));
    view.wheels[1].radius_mm = -1.0;
    view.wheels[2].contact_mm = Some((f64::INFINITY, 0.0));
    view.title = "bad \u{7} title".to_owned();
    let svg = render_setup_svg(&view);
    let doc = roxmltree::Document::parse(&svg).unwrap();
    let wheels = doc
        .descendants()
        .filter(|n| n.attribute("class") == Some("wheel"))
        .count();
    assert_eq!(wheels, 2 * 3);
    assert!(svg.contains("3 item(s) with non-finite values or radius &lt;= 0 not drawn"));

    // An empty view still gives a valid document around the rotation centre.
    let empty = render_setup_svg(&SetupView::default());
    let doc = roxmltree::Document::parse(&empty).unwrap();
    assert!(!empty.contains("NaN") && !empty.contains("inf"));
    assert_eq!(
        doc.descendants()
            .filter(|n| n.attribute("class") == Some("rotation-centre"))
            .count(),
        2
    );
}
