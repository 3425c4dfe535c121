//! The DFT harmonics against independent references: known sinusoids, a naive DFT written
//! with direct trigonometry, and Parseval's identity.

use camloop::core::harmonics::{DftTable, harmonics_um, wrap_deg};

/// Values of `c0 + Σ A·cos(j·ψ − p)` on an N-point grid.
fn synth(n: usize, c0: f64, parts: &[(u32, f64, f64)]) -> Vec<f64> {
    (0..n)
        .map(|k| {
            let psi = std::f64::consts::TAU * k as f64 / n as f64;
            c0 + parts
                .iter()
                .map(|&(j, a, p_deg)| a * (f64::from(j) * psi - p_deg.to_radians()).cos())
                .sum::<f64>()
        })
        .collect()
}

/// Pseudo-random values in [−1, 1) from a fixed LCG.
fn noise(n: usize, seed: u64) -> Vec<f64> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        })
        .collect()
}

#[test]
fn known_sinusoids_come_back_with_their_amplitude_and_phase() {
    let parts = [
        (1, 3.0, 25.0),
        (2, 1.5, -170.0),
        (7, 0.8, 90.0),
        (17, 0.25, 179.0),
    ];
    // 360 (the gauge), 359 (prime, no FFT-friendly factor), 100, 40 (orders up to 20 only).
    for n in [360usize, 359, 100, 40] {
        let values = synth(n, 4.0, &parts);
        let h = harmonics_um(&values, 50);
        assert_eq!(h.len(), 50.min(n / 2), "N = {n}");
        for (i, harmonic) in h.iter().enumerate() {
            assert_eq!(harmonic.order, i as u32 + 1);
            match parts.iter().find(|p| p.0 == harmonic.order) {
                Some(&(_, a, p)) => {
                    // Exact in exact arithmetic; 1e-12 covers rounding of ~360 terms.
                    assert!(
                        (harmonic.amplitude_um - a).abs() < 1e-12,
                        "N {n}: {harmonic:?}"
                    );
                    assert!(
                        wrap_deg(harmonic.phase_deg - p).abs() < 1e-9,
                        "N {n}: {harmonic:?}"
                    );
                }
                None => assert!(harmonic.amplitude_um < 1e-12, "N {n}: {harmonic:?}"),
            }
        }
    }
}

#[test]
fn phase_locates_the_maximum() {
    // A single order-3 cosine peaking at 40°: phase = 3·40° = 120°.
    let values: Vec<f64> = (0..360)
        .map(|k| 2.0 * (3.0 * (f64::from(k) - 40.0)).to_radians().cos())
        .collect();
    let h = harmonics_um(&values, 3);
    assert!((h[2].amplitude_um - 2.0).abs() < 1e-12);
    assert!((h[2].phase_deg - 120.0).abs() < 1e-9, "{:?}", h[2]);
}

#[test]
fn matches_a_naive_dft_on_arbitrary_data() {
    for n in [360usize, 181, 64, 9] {
        let values = noise(n, n as u64);
        let table = DftTable::new(n);
        for j in 0..=n / 2 {
            let (a, b) = table.coefficients(&values, j).expect("order within N/2");
            let (mut ra, mut rb) = (0.0, 0.0);
            for (k, x) in values.iter().enumerate() {
                let t = std::f64::consts::TAU * (j * k) as f64 / n as f64;
                ra += x * t.cos();
                rb += x * t.sin();
            }
            let scale = if j == 0 || 2 * j == n { 1.0 } else { 2.0 } / n as f64;
            assert!((a - ra * scale).abs() < 1e-12, "N {n} order {j}: a");
            assert!((b - rb * scale).abs() < 1e-12, "N {n} order {j}: b");
        }
        assert_eq!(
            table.coefficients(&values, n / 2 + 1),
            None,
            "aliasing order refused"
        );
        assert_eq!(
            table.coefficients(&values[1..], 1),
            None,
            "length mismatch refused"
        );
    }
}

#[test]
fn parseval_holds_over_all_orders() {
    // mean(x²) = c0² + ½·Σ A_j² over 0 < j < N/2, + A_{N/2}² for even N (a ±A sequence).
    for n in [360usize, 359, 50, 11] {
        let values = noise(n, 7 + n as u64);
        let energy = values.iter().map(|x| x * x).sum::<f64>() / n as f64;
        let table = DftTable::new(n);
        let (c0, _) = table.coefficients(&values, 0).expect("order 0");
        let h = table.harmonics(&values, u32::MAX);
        assert_eq!(h.len(), n / 2);
        let mut spectral = c0 * c0;
        for harmonic in &h {
            let a2 = harmonic.amplitude_um * harmonic.amplitude_um;
            spectral += if 2 * harmonic.order as usize == n {
                a2
            } else {
                0.5 * a2
            };
        }
        assert!(
            (energy - spectral).abs() < 1e-12 * energy.max(1.0),
            "N {n}: {energy} vs {spectral}"
        );
    }
}

#[test]
fn nyquist_order_is_a_signed_cosine() {
    let alternating: Vec<f64> = (0..8)
        .map(|k| if k % 2 == 0 { 1.5 } else { -1.5 })
        .collect();
    let h = harmonics_um(&alternating, 50);
    assert_eq!(h.len(), 4);
    assert!((h[3].amplitude_um - 1.5).abs() < 1e-12 && h[3].phase_deg.abs() < 1e-9);
    let negated: Vec<f64> = alternating.iter().map(|x| -x).collect();
    let h = harmonics_um(&negated, 50);
    assert!((h[3].amplitude_um - 1.5).abs() < 1e-12);
    assert!((h[3].phase_deg - 180.0).abs() < 1e-9, "{:?}", h[3]);
}

#[test]
fn wrap_keeps_angles_in_the_half_open_interval() {
    for (input, expected) in [
        (180.0, 180.0),
        (-180.0, 180.0),
        (190.0, -170.0),
        (-190.0, 170.0),
        (720.5, 0.5),
        (0.0, 0.0),
    ] {
        assert!(
            (wrap_deg(input) - expected).abs() < 1e-12,
            "{input} → {}",
            wrap_deg(input)
        );
    }
}

#[test]
fn empty_input_gives_no_harmonics() {
    assert!(harmonics_um(&[], 50).is_empty());
    assert!(harmonics_um(&[1.0], 50).is_empty());
}
