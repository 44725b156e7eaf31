//! The general surfaces as data, below the `Flow` trait whose answers
//! they are and below `surface`, which finds and resolves their
//! crossings: what a surface is (an event or a switch), the region bits a
//! trajectory carries (its sides of the switches, the switches it slides
//! on, the event it is held on), the surfaces' values and rates at one
//! state or a batch of them, and the switches a sliding region slides on.

/// General surfaces a flow may have (events and switches together).
pub const MAX_SURFACES: usize = 4;

/// What crossing a surface does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Surface {
    /// An event: the motion lives where g ≤ 0; where g crosses 0 from
    /// below, the reset maps the state.
    Event,
    /// Switch number `bit` of the field: no reset, the trajectory's region
    /// flips that bit.
    Switch { bit: u32 },
}

/// Region bits from this one up mark a trajectory sliding on a switch:
/// bit `SLIDING + j` for surface j; the bits below are the sides.
pub const SLIDING: u32 = 16;

/// The side bits of a region (what a flow's fields are indexed by).
#[inline(always)]
pub fn sides(region: u32) -> u32 {
    region & ((1 << SLIDING) - 1)
}

/// Region bits from this one up mark a trajectory held on an event's
/// surface (sticking): bit `HELD + j` for surface j.
pub const HELD: u32 = 24;

/// The surfaces a trajectory in `region` slides on: bit j for surface j.
#[inline(always)]
pub fn sliding_set(region: u32) -> u32 {
    (region >> SLIDING) & ((1 << (HELD - SLIDING)) - 1)
}

/// The event a trajectory in `region` is held on, if any.
#[inline(always)]
pub fn held_on(region: u32) -> Option<usize> {
    let set = region >> HELD;
    (set != 0).then(|| set.trailing_zeros() as usize)
}

/// Whether a trajectory in `region` slides on a switch or is held on an
/// event: its steps take the resolution path.
#[inline(always)]
pub fn is_constrained(region: u32) -> bool {
    region >> SLIDING != 0
}

/// Whether a trajectory in `region` slides on any switch.
#[inline(always)]
pub fn is_sliding(region: u32) -> bool {
    sliding_set(region) != 0
}

/// The region of a trajectory in `region` that slides on surface j as well.
pub fn sliding_on(region: u32, j: usize) -> u32 {
    region | 1 << (SLIDING + j as u32)
}

/// The region of a trajectory in `region` that leaves its sliding on
/// surface j (switch bit `bit`) to the positive side or the negative one;
/// the other sliding switches keep sliding.
pub fn leaving(region: u32, j: usize, bit: u32, to_plus: bool) -> u32 {
    let region = region & !(1 << (SLIDING + j as u32));
    if to_plus {
        region | 1 << bit
    } else {
        region & !(1 << bit)
    }
}

/// The most switches one motion slides on at once.
pub(super) const MAX_SLIDING: usize = MAX_SURFACES;

/// The switches a trajectory in a region slides on: their surfaces and
/// bits in order, and the region's sides with all of them on the
/// negative side (F₀'s region). Gathered once per sliding sub-step, not
/// per evaluation of the field.
#[derive(Clone, Copy, Debug)]
pub struct SlidingSet {
    pub(super) members: [(usize, u32); MAX_SLIDING],
    pub(super) n: usize,
    pub(super) base: u32,
}

impl SlidingSet {
    /// The switches slid on: (surface, bit), in the surfaces' order.
    pub fn members(&self) -> &[(usize, u32)] {
        &self.members[..self.n]
    }

    /// The region with every sliding switch on its negative side (F₀'s).
    pub fn base(&self) -> u32 {
        self.base
    }

    /// The set of a trajectory in `region` of a flow with these surfaces.
    pub fn of(surfaces: &[Surface], region: u32) -> Self {
        let set = sliding_set(region);
        let mut members = [(0, 0); MAX_SLIDING];
        let mut n = 0;
        for (j, s) in surfaces.iter().enumerate() {
            if let (true, Surface::Switch { bit }) = (set >> j & 1 == 1, *s) {
                members[n] = (j, bit);
                n += 1;
            }
        }
        let base = members[..n]
            .iter()
            .fold(sides(region), |r, &(_, bit)| r & !(1 << bit));
        SlidingSet { members, n, base }
    }
}

/// g of every surface at one state, and its rate ∇g·F along a region's
/// field (only the first `surfaces().len()` are meaningful).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SurfaceValues {
    pub g: [f64; MAX_SURFACES],
    pub rate: [f64; MAX_SURFACES],
}

/// [`SurfaceValues`] of W trajectories, structure of arrays, as a
/// batch's evaluation gives them and the step loop's detection reads them,
/// a vector per row: g of surface j in row 2j, its rate in row 2j + 1 (the
/// outputs of a model's surfaces' tape, `model::compiled::Field::surfaces`,
/// which its native code writes in place). A model with fewer surfaces
/// leaves the rows past its own at their zeros, unwritten.
/// 32-byte aligned, for the AVX2 loads of the rows.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(32))]
pub struct SurfaceBatch<const W: usize> {
    pub rows: [[f64; W]; 2 * MAX_SURFACES],
}

impl<const W: usize> Default for SurfaceBatch<W> {
    fn default() -> Self {
        SurfaceBatch {
            rows: [[0.0; W]; 2 * MAX_SURFACES],
        }
    }
}

impl<const W: usize> SurfaceBatch<W> {
    /// g of surface j in every slot.
    #[inline(always)]
    pub fn g(&self, j: usize) -> &[f64; W] {
        &self.rows[2 * j]
    }

    /// The rate of surface j in every slot.
    #[inline(always)]
    pub fn rate(&self, j: usize) -> &[f64; W] {
        &self.rows[2 * j + 1]
    }

    /// Slot k's values.
    #[inline(always)]
    pub fn column(&self, k: usize) -> SurfaceValues {
        let mut v = SurfaceValues::default();
        for j in 0..MAX_SURFACES {
            v.g[j] = self.g(j)[k];
            v.rate[j] = self.rate(j)[k];
        }
        v
    }

    /// Sets slot k's values.
    #[inline(always)]
    pub fn set_column(&mut self, k: usize, v: &SurfaceValues) {
        for j in 0..MAX_SURFACES {
            self.rows[2 * j][k] = v.g[j];
            self.rows[2 * j + 1][k] = v.rate[j];
        }
    }

    /// Slot k's values taken from `other` (a batch evaluated in slot k's
    /// region).
    #[inline(always)]
    pub fn take_column(&mut self, k: usize, other: &Self) {
        for (row, from) in self.rows.iter_mut().zip(&other.rows) {
            row[k] = from[k];
        }
    }
}

impl Surface {
    /// The orientation of g for a trajectory in `region`: +1 where the
    /// crossing to watch for is g rising through 0 (an event, or a switch
    /// whose side is the negative one), -1 where it is g falling.
    #[inline(always)]
    pub fn orientation(self, region: u32) -> f64 {
        match self {
            Surface::Switch { bit } if (region >> bit) & 1 == 1 => -1.0,
            _ => 1.0,
        }
    }
}
