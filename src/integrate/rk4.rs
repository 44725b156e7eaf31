//! The classical fourth-order Runge–Kutta step (the paper's integrator).

use super::Flow;

/// One RK4 step of size h from (t, y):
/// k1 = F(t, y), k2 = F(t + h/2, y + h/2·k1), k3 = F(t + h/2, y + h/2·k2),
/// k4 = F(t + h, y + h·k3), y + h/6·(k1 + 2k2 + 2k3 + k4).
#[inline]
pub fn step<const D: usize, F: Flow<D> + ?Sized>(
    flow: &F,
    t: f64,
    y: &[f64; D],
    h: f64,
) -> [f64; D] {
    let half = 0.5 * h;
    let k1 = flow.rhs(t, y);
    let k2 = flow.rhs(t + half, &axpy(y, half, &k1));
    let k3 = flow.rhs(t + half, &axpy(y, half, &k2));
    let k4 = flow.rhs(t + h, &axpy(y, h, &k3));
    let sixth = h / 6.0;
    std::array::from_fn(|i| y[i] + sixth * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]))
}

/// y + a·k
#[inline]
fn axpy<const D: usize>(y: &[f64; D], a: f64, k: &[f64; D]) -> [f64; D] {
    std::array::from_fn(|i| y[i] + a * k[i])
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Decay;
    impl Flow<1> for Decay {
        fn rhs(&self, _t: f64, y: &[f64; 1]) -> [f64; 1] {
            [-y[0]]
        }
    }

    #[test]
    fn one_step_is_the_fourth_order_taylor_polynomial() {
        // For y' = -y, RK4's stability function is 1 - h + h²/2 - h³/6 + h⁴/24.
        let h = 0.1_f64;
        let expected = 1.0 - h + h * h / 2.0 - h.powi(3) / 6.0 + h.powi(4) / 24.0;
        assert!((step(&Decay, 0.0, &[1.0], h)[0] - expected).abs() < 1e-16);
    }
}
