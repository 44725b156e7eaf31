//! QR accumulation, by its defining properties.

use lyapsweep::method::qr::{qr_positive, QrAccumulator};
use nalgebra::{Const, DimMin, SMatrix};
use proptest::prelude::*;

fn check<const D: usize>(entries: &[f64], previous: &[f64]) -> Result<(), TestCaseError>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let j = SMatrix::<f64, D, D>::from_iterator(entries.iter().copied());
    // A previous frame Q_{n-1}: orthonormal, from the QR of a random matrix.
    let (q_prev, _) = qr_positive(SMatrix::<f64, D, D>::from_iterator(
        previous.iter().copied(),
    ));
    let (q, r) = qr_positive(j * q_prev);
    let scale = j.norm().max(1.0);
    prop_assert!(
        (q * r - j * q_prev).norm() < 1e-12 * scale,
        "Q R != J Q_prev"
    );
    prop_assert!(
        (q.transpose() * q - SMatrix::<f64, D, D>::identity()).norm() < 1e-13,
        "Q not orthonormal"
    );
    for i in 0..D {
        prop_assert!(r[(i, i)] > 0.0, "R[{i}{i}] = {}", r[(i, i)]);
        for k in 0..i {
            prop_assert!(
                r[(i, k)] == 0.0 || r[(i, k)].abs() < 1e-14 * scale,
                "R not upper triangular"
            );
        }
    }
    Ok(())
}

fn invertible(d: usize) -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(-10.0..10.0f64, d * d).prop_filter("invertible", move |m| {
        let m = nalgebra::DMatrix::from_column_slice(d, d, m);
        m.determinant().abs() > 1e-3
    })
}

proptest! {
    #[test]
    fn qr_of_2x2(j in invertible(2), p in invertible(2)) { check::<2>(&j, &p)?; }
    #[test]
    fn qr_of_3x3(j in invertible(3), p in invertible(3)) { check::<3>(&j, &p)?; }
    #[test]
    fn qr_of_4x4(j in invertible(4), p in invertible(4)) { check::<4>(&j, &p)?; }
}

#[test]
fn exponents_of_a_constant_diagonal_map_are_its_log_moduli() {
    let mut acc = QrAccumulator::<3>::new();
    let j = SMatrix::<f64, 3, 3>::from_diagonal(&nalgebra::Vector3::new(2.0, -0.5, 0.1));
    // The start frame's projection onto the axes stays in the sums until
    // the frame is aligned (gaps of ln 4 and ln 5 a step: e^-55 in 40).
    for _ in 0..40 {
        acc.push(&j);
    }
    acc.restart_sums();
    for _ in 0..10 {
        acc.push(&j);
    }
    let l = acc.exponents(0.5);
    let expected = [2.0_f64.ln() / 0.5, 0.5_f64.ln() / 0.5, 0.1_f64.ln() / 0.5];
    for (a, b) in l.iter().zip(expected) {
        assert!((a - b).abs() < 1e-14, "{l:?}");
    }
}

#[test]
fn sum_of_log_diagonals_is_log_abs_determinant() {
    // Π R_ii = |det J| for every factorisation: the identity behind the sum rule.
    let j = SMatrix::<f64, 2, 2>::new(0.3, -1.7, 2.2, 0.9);
    let mut acc = QrAccumulator::<2>::new();
    let d = acc.push(&j);
    assert!((d[0] * d[1] - j.determinant().abs()).abs() < 1e-14);
}
