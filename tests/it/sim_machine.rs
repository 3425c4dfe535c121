//! Each machine error does what physics says it should, judged on the demo lobe ground from
//! a 360-point POLY table (which alone leaves < 0.001 µm, see sim_envelope.rs), and the
//! default machine lands near the published 16 µm.

use crate::sim_support;

use camloop::core::fit::TableForm;
use camloop::core::geometry::Follower;
use camloop::sim::{GrinderConfig, Harmonic};
use sim_support::*;

/// 0.1° grid.
const FINE: usize = 3600;

fn poly_error_um(config: GrinderConfig) -> Vec<f64> {
    let sim = demo_sim(config, Follower::Flat, 7);
    let ground = sim
        .grind(&demo_table(Follower::Flat, 360, TableForm::Poly))
        .unwrap();
    error_um(&ground.lift_on_grid(FINE), &nominal_on_grid(FINE))
}

/// The same wheel-centre path with a wheel ΔR bigger: the outline is the inner parallel
/// curve at distance ΔR, so a flat follower's lift drops by exactly ΔR everywhere (the
/// wheel is bigger than the control believes and cuts deeper).
#[test]
fn wheel_bigger_than_believed_grinds_the_lift_uniformly_lower() {
    let error = poly_error_um(GrinderConfig {
        wheel_size_error_um: 5.0,
        ..GrinderConfig::perfect()
    });
    for (j, e) in error.iter().enumerate() {
        assert!((e + 5.0).abs() < 0.01, "{e} µm at {}°", j as f64 / 10.0);
    }
}

/// A pure delay of ωτ in X: d_act(c) = d(c − ωτ) ≈ d(c) − ωτ·d'(c), and a wheel-centre
/// change Δd at c moves the flat support at ψ by Δd·cos(c − ψ). So the lift error is
/// −ωτ·d'(c(ψ))·cos(c − ψ) to first order, with c(ψ) = ψ + atan2(h', Rb + h + R). The
/// neglected second-order term ½(ωτ)²·d'' is ≈ 0.03 µm of ≈ 14 µm here, so 2 % holds where
/// the error peaks (the brief asks for 10 %); elsewhere the difference stays below 0.1 µm.
/// The derivative d' comes from the core's exact geometry by central differences.
#[test]
fn servo_lag_error_follows_the_x_velocity() {
    let config = GrinderConfig {
        servo_lag_ms: 0.45,
        ..GrinderConfig::perfect()
    };
    let lag_rad = config.lag_rad();
    let error = poly_error_um(config);
    let part = demo_part(Follower::Flat);
    let lift = demo_lift();
    let step_deg = 1e-3;
    let predicted: Vec<f64> = (0..FINE)
        .map(|j| {
            let psi_deg = j as f64 / 10.0;
            let l = lift.eval(psi_deg.to_radians());
            let tilt = l.dh_mm.atan2(BASE_RADIUS_MM + l.h_mm + WHEEL_RADIUS_MM);
            let c_deg = psi_deg + tilt.to_degrees();
            let d_prime = (part.d_at_c_deg(c_deg + step_deg).unwrap()
                - part.d_at_c_deg(c_deg - step_deg).unwrap())
                / (2.0 * step_deg.to_radians());
            -lag_rad * d_prime * tilt.cos() * 1000.0
        })
        .collect();
    let (peak, at) = max_abs(&predicted);
    assert!(peak > 10.0, "predicted peak {peak} µm");
    assert!(
        (error[at] - predicted[at]).abs() < 0.02 * peak,
        "at {}°: error {} µm, predicted {} µm",
        at as f64 / 10.0,
        error[at],
        predicted[at]
    );
    // On each flank the error peaks where the X velocity does.
    for half in [0..FINE / 2, FINE / 2..FINE] {
        let (_, predicted_at) = max_abs(&predicted[half.clone()]);
        let (_, actual_at) = max_abs(&error[half.clone()]);
        assert!(
            actual_at.abs_diff(predicted_at) <= 10,
            "largest error at {}°, largest |dX/dC| effect at {}°",
            (half.start + actual_at) as f64 / 10.0,
            (half.start + predicted_at) as f64 / 10.0
        );
    }
    for j in 0..FINE {
        assert!(
            (error[j] - predicted[j]).abs() < 0.1,
            "at {}°: error {} µm, predicted {} µm",
            j as f64 / 10.0,
            error[j],
            predicted[j]
        );
    }
    // Leading the rise is lagging behind it: the rising flank (d' > 0) is ground low.
    assert!(error[1400] < -5.0 && error[2200] > 5.0);
}

/// Harmonics of the wheel-centre distance on the base circle (the lobe spans 100°–260°):
/// there c = ψ up to g'/d ≈ 2e-5 rad, so the lift error is Σ A·cos(kψ + φ) to within
/// d·(g'/d)²/2 + |g'|·g'/d ≈ 1e-7 mm.
#[test]
fn harmonics_show_on_the_base_circle_as_themselves() {
    let harmonics = vec![
        Harmonic {
            order: 2,
            amplitude_um: 2.0,
            phase_deg: 30.0,
        },
        Harmonic {
            order: 5,
            amplitude_um: 0.7,
            phase_deg: -45.0,
        },
    ];
    let error = poly_error_um(GrinderConfig {
        harmonics: harmonics.clone(),
        ..GrinderConfig::perfect()
    });
    for j in (0..900).chain(2700..FINE) {
        let psi = (j as f64 / 10.0).to_radians();
        let expected: f64 = harmonics
            .iter()
            .map(|h| h.amplitude_um * (f64::from(h.order) * psi + h.phase_deg.to_radians()).cos())
            .sum();
        assert!(
            (error[j] - expected).abs() < 1e-3,
            "at {}°: {} µm, expected {expected} µm",
            j as f64 / 10.0,
            error[j]
        );
    }
}

/// The default machine is sized like the published case: about 16 µm of maximum profile
/// error (no datum or fit removed) before any compensation, from a POLY or a G1 table.
#[test]
fn default_machine_leaves_about_16_um_uncompensated() {
    for form in [TableForm::Poly, TableForm::G1] {
        let sim = demo_sim(GrinderConfig::default(), Follower::Flat, 7);
        let ground = sim.grind(&demo_table(Follower::Flat, 360, form)).unwrap();
        let error = error_um(&ground.lift_on_grid(FINE), &nominal_on_grid(FINE));
        let (worst, at) = max_abs(&error);
        assert!(
            (13.0..19.0).contains(&worst),
            "{form:?}: max error {worst} µm at {}°",
            at as f64 / 10.0
        );
    }
}

/// The C speed enters only through ω·τ: doubling the speed and halving the lag grinds the
/// same part.
#[test]
fn lag_depends_on_speed_times_delay() {
    let a = poly_error_um(GrinderConfig {
        c_speed_rpm: 30.0,
        servo_lag_ms: 0.4,
        ..GrinderConfig::perfect()
    });
    let b = poly_error_um(GrinderConfig {
        c_speed_rpm: 60.0,
        servo_lag_ms: 0.2,
        ..GrinderConfig::perfect()
    });
    let worst = a
        .iter()
        .zip(&b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    assert!(worst < 1e-9, "{worst} µm");
}
