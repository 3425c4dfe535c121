//! Accuracy of the whole measurement path (assemble → average → analyse) on synthetic lobes
//! with a known phase, base-circle offset, profile error, noise and one corrupted revolution.
//!
//! What the fit may legitimately absorb: it removes from the error everything along the
//! constant 1 (size) and along the nominal slope h'(ψ − φ) (rotation). An injected profile
//! error with a component along those would, correctly, be reported partly as phase or
//! size. So the injected error is made exactly orthogonal to both on the measurement grid
//! (two correction terms, both windowed to the lift region, are solved for below); then the
//! true (φ, δ) are the least-squares optimum of the noise-free data, and the reported
//! profile error must equal the injected one up to noise.
//!
//! Tolerances (from the brief), against the noise floor they leave:
//! - profile error within 0.3 µm RMS: the mean of 3 revolutions with σ = 0.3 µm has
//!   σ/√3 ≈ 0.17 µm RMS per angle; over 360 angles that RMS scatters by ~4 %.
//! - phase within 0.02°: the noise moves φ by about 0.17 µm / sqrt(Σ h'²) ≈ 1e-4°.
//! - base-circle offset within 0.2 µm: the noise moves δ by about 0.17 µm / √360 ≈ 0.01 µm.

use crate::cycloid_cam;
use camloop::core::analysis::{LobeOptions, analyse_lobe};
use camloop::core::measure::{
    AssemblyLimits, MeasurementHeader, RawMeasurement, RawSample, check_and_average,
};
use cycloid_cam::{RISE_DEG, RISE_FROM_DEG, cam};

const N: usize = 360;
const REVS: u32 = 4;
const NOISE_UM: f64 = 0.3;

/// splitmix64 with Box–Muller: a seeded Gaussian source, independent of any crate.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in (0, 1].
    fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) + 1) as f64 / (1u64 << 53) as f64
    }
    fn gaussian(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The injected profile error on the grid, µm: a few harmonics of the lift region under a
/// sin² window (in the lobe's own frame, so it moves with the phase), plus the two windowed
/// correction terms that make it orthogonal to 1 and to h'(ψ − φ).
fn injected_error_um(phase_deg: f64, rng: &mut Rng) -> Vec<f64> {
    let span = 2.0 * RISE_DEG;
    let window = |psi: f64| {
        let u = (psi - phase_deg - RISE_FROM_DEG).rem_euclid(360.0) / span;
        if u <= 1.0 {
            ((std::f64::consts::PI * u).sin().powi(2), u)
        } else {
            (0.0, u)
        }
    };
    let (p1, p2, p3) = (
        rng.uniform() * 6.0,
        rng.uniform() * 6.0,
        rng.uniform() * 6.0,
    );
    let mut raw = Vec::with_capacity(N);
    let mut w_col = Vec::with_capacity(N);
    let mut wh_col = Vec::with_capacity(N);
    let mut slope = Vec::with_capacity(N);
    for k in 0..N {
        let psi = k as f64 * 360.0 / N as f64;
        let (w, u) = window(psi);
        let t = std::f64::consts::TAU * u;
        let g =
            2.0 * (2.0 * t + p1).sin() + 1.5 * (3.0 * t + p2).cos() + 0.8 * (5.0 * t + p3).sin();
        let dh = cam(psi - phase_deg).1;
        raw.push(w * g);
        w_col.push(w);
        wh_col.push(w * dh * 10.0);
        slope.push(dh);
    }
    let ones = vec![1.0; N];
    // Solve for α, β: ⟨raw + α·w + β·w·h', 1⟩ = 0 and ⟨…, h'⟩ = 0.
    let (a11, a12, b1) = (dot(&w_col, &ones), dot(&wh_col, &ones), -dot(&raw, &ones));
    let (a21, a22, b2) = (
        dot(&w_col, &slope),
        dot(&wh_col, &slope),
        -dot(&raw, &slope),
    );
    let det = a11 * a22 - a12 * a21;
    let alpha = (b1 * a22 - a12 * b2) / det;
    let beta = (a11 * b2 - a21 * b1) / det;
    let e: Vec<f64> = (0..N)
        .map(|k| raw[k] + alpha * w_col[k] + beta * wh_col[k])
        .collect();
    // The construction itself, checked: orthogonal to rounding.
    assert!(dot(&e, &ones).abs() < 1e-9, "injected error has a mean");
    assert!(
        dot(&e, &slope).abs() < 1e-9,
        "injected error has a phase part"
    );
    e
}

struct Case {
    phase_deg: f64,
    offset_um: f64,
    error_um: Vec<f64>,
    bad_revolution: u32,
    raw: RawMeasurement,
}

fn synthetic(seed: u64) -> Case {
    let mut rng = Rng(seed);
    let phase_deg = (rng.uniform() - 0.5) * 2.0;
    let offset_um = (rng.uniform() - 0.5) * 10.0;
    let error_um = injected_error_um(phase_deg, &mut rng);
    let bad_revolution = (rng.next_u64() % u64::from(REVS)) as u32;
    let bump_at_deg = rng.uniform() * 360.0;
    let mut samples = Vec::with_capacity(N * REVS as usize);
    for r in 0..REVS {
        for (k, e_um) in error_um.iter().enumerate() {
            let psi = k as f64 * 360.0 / N as f64;
            let mut um = offset_um + e_um + NOISE_UM * rng.gaussian();
            if r == bad_revolution {
                // 20 µm bump, 8° wide (1σ 4°), anywhere on the revolution
                let d = (psi - bump_at_deg + 180.0).rem_euclid(360.0) - 180.0;
                um += 20.0 * (-0.5 * (d / 4.0).powi(2)).exp();
            }
            samples.push(RawSample {
                revolution: r,
                angle_index: k as u32,
                lift_mm: cam(psi - phase_deg).0 + um / 1000.0,
            });
        }
    }
    let raw = RawMeasurement {
        header: MeasurementHeader {
            machine: "m1".into(),
            part: "p1".into(),
            lobe: "in1".into(),
            revolutions: REVS,
            points_per_rev: N as u32,
        },
        samples,
        origin: format!("synthetic seed {seed}"),
    };
    Case {
        phase_deg,
        offset_um,
        error_um,
        bad_revolution,
        raw,
    }
}

fn rms(a: &[f64], b: &[f64]) -> f64 {
    (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
}

#[test]
fn recovers_phase_offset_and_profile_error_and_drops_the_corrupted_revolution() {
    for seed in 1..=20u64 {
        let case = synthetic(seed);
        let avg = check_and_average(&case.raw, &AssemblyLimits::default())
            .unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        let report = analyse_lobe(&avg, &cam, &LobeOptions::default())
            .unwrap_or_else(|e| panic!("seed {seed}: {e}"));

        let dropped: Vec<u32> = report
            .dropped_revolutions
            .iter()
            .map(|d| d.revolution)
            .collect();
        assert_eq!(dropped, vec![case.bad_revolution], "seed {seed}");
        assert!(
            report.dropped_revolutions[0].max_deviation_um > 15.0,
            "seed {seed}: the bump is 20 µm, {:?}",
            report.dropped_revolutions[0]
        );
        let used: Vec<u32> = (0..REVS).filter(|&r| r != case.bad_revolution).collect();
        assert_eq!(report.revolutions_used, used, "seed {seed}");

        let profile_rms = rms(&report.profile_error_um, &case.error_um);
        assert!(
            profile_rms < 0.3,
            "seed {seed}: profile error off by {profile_rms} µm RMS"
        );
        let phase_off = (report.phase_error_deg - case.phase_deg).abs();
        assert!(phase_off < 0.02, "seed {seed}: phase off by {phase_off}°");
        let offset_off = (report.base_radius_error_um - case.offset_um).abs();
        assert!(
            offset_off < 0.2,
            "seed {seed}: offset off by {offset_off} µm"
        );

        // error_um has nothing fitted: it is h(ψ − φ) − h(ψ) + δ + e, up to the same noise.
        let expected_raw: Vec<f64> = (0..N)
            .map(|k| {
                let psi = k as f64 * 360.0 / N as f64;
                (cam(psi - case.phase_deg).0 - cam(psi).0) * 1000.0
                    + case.offset_um
                    + case.error_um[k]
            })
            .collect();
        let raw_rms = rms(&report.error_um, &expected_raw);
        assert!(
            raw_rms < 0.3,
            "seed {seed}: error_um off by {raw_rms} µm RMS"
        );

        // No eccentricity was injected and the injected error is zero on the base circle:
        // the fitted first harmonic there is noise, about 2·0.17 µm·sqrt(2/220) ≈ 0.05 µm.
        let runout = report.runout_um.expect("base circle spans about 220°");
        assert!(
            runout < 0.2,
            "seed {seed}: runout {runout} µm from noise alone"
        );

        // Repeatability of the 3 good revolutions: the sample σ (n − 1) of 3 values from
        // σ = 0.3 µm noise has mean c4(3)·σ = 0.886·0.3 = 0.266 µm and spread
        // σ·sqrt(1 − c4²) = 0.139 µm per angle, so its mean over 360 angles lies within
        // 0.266 ± 0.03 µm (4 standard errors). The population σ (n) would give 0.217 µm.
        let mean_sd = report.repeatability_um.iter().sum::<f64>() / N as f64;
        assert!(
            (0.236..0.296).contains(&mean_sd),
            "seed {seed}: mean repeatability {mean_sd} µm"
        );
    }
}
