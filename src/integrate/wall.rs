//! A rigid wall (a stop) as data, and the stop test of a step (does it
//! end across a surface, or turn back within reach of it): what the `Flow`
//! trait, the step loops' detection (the vector loop of `integrate`, the
//! generated ones, the shaders') and the impact code share, below all of
//! them. Locating a crossing is `locate`'s, applying it `impact`'s.

/// A rigid wall at `position` on coordinate `coordinate`, whose rate is
/// coordinate `velocity`, with coefficient of restitution `restitution`.
/// `side` +1 confines the motion to coordinate ≤ position (a wall
/// approached from below), -1 to coordinate ≥ position.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wall {
    pub position: f64,
    pub restitution: f64,
    pub coordinate: usize,
    pub velocity: usize,
    pub side: f64,
}

/// Walls a flow may have (the crossings of each are counted apart).
pub const MAX_WALLS: usize = 4;

impl Wall {
    /// The seed's wall: coordinate 0 (X) stopped from below, coordinate 1 its velocity.
    pub fn above(position: f64, restitution: f64) -> Wall {
        Wall {
            position,
            restitution,
            coordinate: 0,
            velocity: 1,
            side: 1.0,
        }
    }

    /// How far y lies beyond the wall (> 0: behind it).
    #[inline(always)]
    pub fn gap<const D: usize>(&self, y: &[f64; D]) -> f64 {
        self.side * (y[self.coordinate] - self.position)
    }

    /// The speed towards the wall (> 0: approaching).
    #[inline(always)]
    pub fn speed<const D: usize>(&self, y: &[f64; D]) -> f64 {
        self.side * y[self.velocity]
    }

    /// y moved onto the wall with approach speed `speed`.
    #[inline]
    pub(super) fn on_wall<const D: usize>(&self, mut y: [f64; D], speed: f64) -> [f64; D] {
        y[self.coordinate] = self.position;
        y[self.velocity] = self.side * speed;
        y
    }
}

/// How far, in units of h·(s0 - s1), the event mechanism lets a step that
/// turns back rise beyond its higher end before it stops looking: twice
/// the most its cubic Hermite interpolant can rise (4/27, the peak of the
/// basis functions θ(1-θ)² and θ²(1-θ)).
pub const TURN_REACH: f64 = 8.0 / 27.0;

/// Whether a step of size h whose speed towards the wall turns from s0 > 0
/// to s1 < 0, both ends short of it (gaps g0, g1 <= 0), may pass the wall
/// in between, and so needs the re-step to its Hermite peak that decides
/// (`locate::locate_newton`).
///
/// The interpolant g0·H00 + g1·H01 + h·s0·H10 + h·s1·H11 (H00 + H01 = 1,
/// 0 <= H10, -H11 <= 4/27) stays below max(g0, g1) + (4/27)·h·(s0 - s1).
/// RK4 re-stepped to the peak differs from it by O(h⁴), the step's whole
/// rise is O(h²): with twice the bound as the reach, a turn ignored here
/// could pass the wall only if RK4's sub-step overshot the cubic by more
/// than the step's whole rise, a step that does not resolve the motion.
/// Most turns happen far from any wall (97% of those on the speed issue's
/// sweep at 0.1 or more short of it), and each one that passed this test
/// left the step loop to find nothing.
///
/// Written as two comparisons rather than a max, so that every path (the
/// step loops, the GPU's) computes it with the same operations; a NaN
/// anywhere fails both and lets the step through.
#[inline(always)]
pub fn may_turn_past(g0: f64, s0: f64, g1: f64, s1: f64, h: f64) -> bool {
    let reach = TURN_REACH * h * (s0 - s1);
    !((g0 + reach < 0.0) & (g1 + reach < 0.0))
}

/// The stop test of a step of size h along a distance g to a surface
/// (a wall's gap, a general surface's oriented g) whose rate s is g's
/// derivative along the motion (a wall's approach speed): whether the step
/// may cross it, because its end lies beyond (g1 > 0), or because the rate
/// turns from approaching to leaving inside the step (s0 > 0 > s1) within
/// reach of the surface ([`may_turn_past`]). Every Rust path that decides
/// whether a step meets a wall or a surface asks this; the generated step
/// loops and the shaders are its twins.
///
/// `bounded` false counts every turn, out of reach or not: the step loops'
/// cheap first pass, whose hits the bounded test then sifts (or the
/// sliding motion's, which has no reach bound).
///
/// (Bitwise `|` and `&`, not `||` and `&&`: the same answer without
/// branches, so the step loop's test over a batch's slots vectorises.)
#[inline(always)]
pub fn may_reach(g0: f64, s0: f64, g1: f64, s1: f64, h: f64, bounded: bool) -> bool {
    (g1 > 0.0) | ((s0 > 0.0) & (s1 < 0.0) & (!bounded || may_turn_past(g0, s0, g1, s1, h)))
}
