//! The period of a lane's orbit, from its last points: the smallest p whose
//! map brings each of the last p points back within a tolerance of the
//! point p iterations before it.

/// The last 2·`max_period` points of a lane's averaging iterations.
#[derive(Clone, Debug)]
pub struct RecentPoints<const D: usize> {
    /// A ring of the points, `next` the slot the next one takes.
    points: Vec<[f64; D]>,
    next: usize,
    /// Points pushed so far (the ring holds the last of them).
    seen: usize,
    max_period: usize,
    tolerance: f64,
}

/// The relative distance within which a point has come back: far above the
/// rounding of a point computed in `rounding_unit`'s arithmetic (f64 or
/// f32), far below the distance between the points of an orbit.
pub fn return_tolerance(rounding_unit: f64) -> f64 {
    (1e-6_f64).max(1e3 * rounding_unit)
}

impl<const D: usize> RecentPoints<D> {
    pub fn new(max_period: usize, rounding_unit: f64) -> Self {
        RecentPoints {
            // Grown as points come, never reserved whole: a lane holds no
            // more points than it iterates, however large `max_period` is.
            points: Vec::new(),
            next: 0,
            seen: 0,
            max_period,
            tolerance: return_tolerance(rounding_unit),
        }
    }

    pub fn push(&mut self, x: &[f64; D]) {
        if self.max_period == 0 {
            return;
        }
        if self.points.len() < 2 * self.max_period {
            self.points.push(*x);
        } else {
            self.points[self.next] = *x;
        }
        self.next = (self.next + 1) % (2 * self.max_period);
        self.seen += 1;
    }

    /// The point `back` iterations before the last one (0: the last).
    fn back(&self, back: usize) -> &[f64; D] {
        let n = 2 * self.max_period;
        &self.points[(self.next + n - 1 - back) % n]
    }

    /// The orbit's period: the smallest p ≤ max_period for which each of
    /// the last p points lies within the tolerance (relative to
    /// max(1, |x|∞)) of the point p iterations before it; `None` when no p
    /// does (aperiodic, not yet settled, or too few points to tell).
    pub fn period(&self) -> Option<usize> {
        let held = self.points.len().min(self.seen);
        (1..=self.max_period)
            .filter(|&p| 2 * p <= held)
            .find(|&p| (0..p).all(|i| self.close(self.back(i), self.back(i + p))))
    }

    /// The orbit's last points, oldest first, D numbers each: its `period`
    /// points when it has one, else every point held (up to
    /// 2·max_period). The last is the lane's final state.
    pub fn orbit(&self, period: Option<usize>) -> Vec<f64> {
        let held = self.points.len().min(self.seen);
        let n = period.unwrap_or(held).min(held);
        (0..n).rev().flat_map(|i| *self.back(i)).collect()
    }

    fn close(&self, a: &[f64; D], b: &[f64; D]) -> bool {
        let scale = a.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
        a.iter()
            .zip(b)
            .all(|(x, y)| (x - y).abs() <= self.tolerance * scale)
    }
}

#[cfg(test)]
mod tests {
    use super::RecentPoints;

    fn period_of(orbit: &[[f64; 2]], pushes: usize, max_period: usize) -> Option<usize> {
        let mut recent = RecentPoints::<2>::new(max_period, f64::EPSILON);
        for n in 0..pushes {
            recent.push(&orbit[n % orbit.len()]);
        }
        recent.period()
    }

    #[test]
    fn finds_the_smallest_period_that_closes() {
        let three = [[1.0, 0.0], [0.5, 2.0], [-1.0, 3.0]];
        assert_eq!(period_of(&three, 40, 12), Some(3));
        assert_eq!(period_of(&[[2.0, -1.0]], 40, 12), Some(1));
        // Period 3 is past max_period = 2; 6 pushes show period 3 once.
        assert_eq!(period_of(&three, 40, 2), None);
        assert_eq!(period_of(&three, 6, 12), Some(3));
        assert_eq!(period_of(&three, 5, 12), None);
    }

    #[test]
    fn the_orbit_ends_on_the_last_point() {
        let three = [[1.0, 0.0], [0.5, 2.0], [-1.0, 3.0]];
        let mut recent = RecentPoints::<2>::new(12, f64::EPSILON);
        for n in 0..40 {
            recent.push(&three[n % 3]);
        }
        // The 40th point is three[0]; the period's points end there.
        assert_eq!(recent.orbit(Some(3)), vec![0.5, 2.0, -1.0, 3.0, 1.0, 0.0]);
        assert_eq!(recent.orbit(None).len(), 2 * 12 * 2);
        let mut few = RecentPoints::<2>::new(12, f64::EPSILON);
        few.push(&[4.0, 5.0]);
        assert_eq!(few.orbit(None), vec![4.0, 5.0]);
    }

    #[test]
    fn an_orbit_that_does_not_close_has_none() {
        // The logistic map at r = 4: chaotic.
        let mut x = 0.3_f64;
        let mut recent = RecentPoints::<2>::new(12, f64::EPSILON);
        for _ in 0..200 {
            x = 4.0 * x * (1.0 - x);
            recent.push(&[x, 0.0]);
        }
        assert_eq!(recent.period(), None);
        // Rounding-sized differences still close; 1e-4 ones do not.
        let mut recent = RecentPoints::<2>::new(12, f64::EPSILON);
        for n in 0..24 {
            recent.push(&[1.0 + 1e-12 * n as f64, 0.0]);
        }
        assert_eq!(recent.period(), Some(1));
        let mut recent = RecentPoints::<2>::new(12, f64::EPSILON);
        for n in 0..24 {
            recent.push(&[1.0 + 1e-4 * n as f64, 0.0]);
        }
        assert_eq!(recent.period(), None);
    }
}
