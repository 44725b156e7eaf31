//! The sums a lane keeps over its aligning and averaging iterations, and
//! the statuses they decide, whichever backend produced the iterations.

use super::orbit::RecentPoints;
use super::settling::{attractor_tolerance, Settling};
use nalgebra::{Const, DimMin, SMatrix};

use super::plan::LanePlan;
use super::result::{LaneResult, LaneStatus};
use super::settings::{difference_noise, MethodSettings, Tangent};
use super::uncertainty::Uncertainty;
use crate::integrate::MAX_EVENTS;
use crate::method::qr::QrAccumulator;
use crate::system::IterationStats;

/// The estimated exponent error per unit time from finite-difference noise
/// (see [`LaneStatus::Unresolved`]) above which a lane is flagged.
pub const RESOLUTION_BOUND: f64 = 1e-3;

/// An exponent a sliding phase may have collapsed is taken as collapsed
/// (-∞) where its mean ln R_ii per Jacobian is below ln of this many times
/// the finite difference's rounding noise ([`difference_noise`]): a
/// collapsed direction's R_ii is that rounding, and the sub-maps keep a
/// direction that only contracts 1/PART_NOISE above it.
const COLLAPSE_FLOOR: f64 = 10.0;

/// Everything a lane accumulates over its averaging iterations, whichever
/// backend produced the iterations: the QR sums, the impact count, the
/// health counters and the kept bifurcation points.
#[derive(Clone, Debug)]
pub struct LaneAccumulator<const D: usize> {
    qr: QrAccumulator<D>,
    /// The sums of the lane's error estimate.
    uncertainty: Uncertainty<D>,
    period: f64,
    plan: LanePlan,
    transient: usize,
    /// Iterations that turn the frame before the averaging, and how many
    /// of them have been taken.
    align: usize,
    aligned: usize,
    /// Iterations averaged (the settings' less the aligning ones).
    iterations: usize,
    lyapunov: bool,
    /// The first averaged iteration whose point is kept.
    first_kept: usize,
    /// Rounding unit and δ of the run, for the resolution bound.
    noise: Option<(f64, f64, usize)>,
    done: usize,
    impacts: u64,
    crossings: [u64; MAX_EVENTS],
    /// Σ of the iterations' own times and flux terms (Poincaré maps).
    time: f64,
    log_flux: f64,
    chattering: usize,
    sliding: usize,
    grazing: usize,
    grazing_error: f64,
    /// Jacobians taken (iterations × parts).
    parts_done: usize,
    /// The most dimensions any iteration collapsed for certain (sliding on
    /// that many switches at once, an impact with e = 0, sticking on a
    /// stop).
    rank_loss: usize,
    /// The most dimensions any iteration may have collapsed: its sliding
    /// phases, one per switch entered (see `finish`).
    rank_loss_bound: usize,
    noise_squares: f64,
    /// Σ ln of the finite difference's rounding noise over the Jacobians taken.
    log_noise: f64,
    bifurcation: Vec<f64>,
    /// The last averaged points, for the orbit's period.
    recent: RecentPoints<D>,
    /// Whether the result keeps them (see [`MethodSettings::keep_orbit`]).
    keep_orbit: bool,
    jacobians: Option<Vec<f64>>,
    /// The reference's points from the lane's start, for its convergence
    /// time (see [`MethodSettings::keep_settling`]), and the tolerance.
    settling: Option<Settling<D>>,
    settling_tolerance: f64,
    pub(super) failed_at: Option<usize>,
    /// What stopped the lane at `failed_at`.
    pub(super) failure: Failure,
}

/// Why a failed lane stopped: every cause leaves its state non-finite,
/// and this tells them apart for its status.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Failure {
    /// A point that blew up ([`LaneStatus::NonFinite`]).
    NonFinite,
    /// A Poincaré map's trajectory that did not come back to its section
    /// ([`LaneStatus::NoReturn`]).
    NoReturn,
    /// A trajectory ended past the bound on located events
    /// ([`LaneStatus::TooManyEvents`]).
    TooManyEvents,
}

impl Failure {
    /// The cause of the non-finite point `x`, an image whose iteration (of
    /// the reference or of a copy) had the statistics `stats`.
    pub fn of(x: &[f64], stats: &IterationStats) -> Failure {
        if crate::system::is_no_return(x) {
            Failure::NoReturn
        } else {
            Failure::of_stats(stats)
        }
    }

    /// The cause of a non-finite Jacobian or point of an iteration with
    /// the statistics `stats`.
    pub fn of_stats(stats: &IterationStats) -> Failure {
        if stats.too_many_events {
            Failure::TooManyEvents
        } else {
            Failure::NonFinite
        }
    }
}

impl<const D: usize> LaneAccumulator<D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    pub fn new(settings: &MethodSettings, period: f64, plan: LanePlan) -> Self {
        let iterations = settings.iterations - settings.align;
        let kept = settings.bifurcation_points.min(iterations);
        let steps_per_part = if settings.rounding_accumulates {
            plan.steps_per_period / plan.parts
        } else {
            1
        };
        let qr = QrAccumulator::new();
        let last = qr.frame().column(D - 1);
        LaneAccumulator {
            uncertainty: Uncertainty::new(crate::array::from_fn(|i| last[i])),
            qr,
            period,
            plan,
            transient: settings.transient,
            align: settings.align,
            aligned: 0,
            iterations,
            lyapunov: settings.lyapunov,
            first_kept: iterations - kept,
            noise: (settings.tangent == Tangent::FiniteDifference).then_some((
                settings.rounding_unit,
                settings.perturbation,
                steps_per_part,
            )),
            done: 0,
            impacts: 0,
            crossings: [0; MAX_EVENTS],
            time: 0.0,
            log_flux: 0.0,
            chattering: 0,
            sliding: 0,
            grazing: 0,
            grazing_error: 0.0,
            parts_done: 0,
            rank_loss: 0,
            rank_loss_bound: 0,
            noise_squares: 0.0,
            log_noise: 0.0,
            bifurcation: Vec::with_capacity(kept * D),
            recent: RecentPoints::new(settings.max_period, settings.rounding_unit),
            keep_orbit: settings.keep_orbit,
            jacobians: settings.keep_jacobians.then(Vec::new),
            settling: None,
            settling_tolerance: attractor_tolerance(settings.rounding_unit),
            failed_at: None,
            failure: Failure::NonFinite,
        }
    }

    /// Takes one iteration with Jacobians (aligning, then averaging): the reference's new point, the
    /// Jacobians of the map's parts in order (none when exponents are not
    /// wanted) and what happened on the way. Returns false once the lane
    /// has failed.
    pub fn push(
        &mut self,
        next: &[f64; D],
        jacobians: &[SMatrix<f64, D, D>],
        stats: &IterationStats,
    ) -> bool {
        if !all_finite(next) {
            self.fail_at(self.taken(), next, stats);
            return false;
        }
        let scale = next.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        self.record(scale, Some(next), jacobians, stats)
    }

    /// [`push`](Self::push) for a backend that has checked the point itself
    /// and reports only its size `scale` = max |x_i| (the noise estimate's
    /// scale), and the point only when bifurcation points are wanted.
    pub fn record(
        &mut self,
        scale: f64,
        point: Option<&[f64; D]>,
        jacobians: &[SMatrix<f64, D, D>],
        stats: &IterationStats,
    ) -> bool {
        if self.failed_at.is_some() {
            return false;
        }
        let n = self.done;
        if jacobians.iter().any(|j| !j.iter().all(|v| v.is_finite())) {
            // A copy ended past the bound on events leaves the reference
            // finite and its column NaN.
            self.fail_because(self.taken(), Failure::of_stats(stats));
            return false;
        }
        if let (Some(settling), Some(point)) = (self.settling.as_mut(), point) {
            settling.push(point);
        }
        let aligning = self.aligned < self.align;
        if let Some(kept) = self.jacobians.as_mut().filter(|_| !aligning) {
            for j in jacobians {
                kept.extend(j.transpose().iter());
            }
        }
        // An iteration that collapsed phase space (an impact with e = 0,
        // sticking) has a Jacobian of rank D - loss: its last `loss` R_ii are
        // zero in exact arithmetic and rounding here, and the exponents they
        // feed are -∞ (set in `finish`). When nothing is left (loss = D),
        // the frame Q is kept as it is. Sliding phases on several switches
        // one after the other may collapse up to one direction each
        // (`bound`): those R_ii may be rounding too.
        let loss = (stats.rank_loss as usize).min(D);
        let bound = (stats.sliding_phases as usize).max(loss).min(D);
        let kept = D - bound;
        let noise = self.noise.map(|(unit, delta, steps)| {
            difference_noise(unit, scale, steps, delta * scale.max(1.0))
        });
        for j in jacobians.iter().filter(|_| loss < D) {
            let diag = match noise {
                Some(noise) if bound > 0 => {
                    self.qr.push_collapsing(j, COLLAPSE_FLOOR * noise, bound)
                }
                _ => self.qr.push(j),
            };
            if !diag[..kept].iter().all(|r| r.ln().is_finite()) {
                // A singular Jacobian: a direction contracted below what δ and
                // rounding can resolve in one iteration.
                self.fail(self.taken());
                return false;
            }
            self.uncertainty.push(j, !aligning);
            if aligning {
                continue;
            }
            if let Some(noise) = noise {
                self.log_noise += noise.ln();
                if bound == 0 {
                    let smallest = diag.iter().fold(f64::INFINITY, |m, &r| m.min(r));
                    self.noise_squares += (noise / smallest).powi(2);
                }
            }
        }
        if aligning {
            self.aligned += 1;
            if self.aligned == self.align {
                self.qr.restart_sums();
            }
            return true;
        }
        self.rank_loss = self.rank_loss.max(loss);
        self.rank_loss_bound = self.rank_loss_bound.max(bound);
        self.parts_done += jacobians.len();
        self.impacts += u64::from(stats.impacts);
        for (c, &s) in self.crossings.iter_mut().zip(&stats.crossings) {
            *c += u64::from(s);
        }
        self.time += stats.time;
        self.log_flux += stats.log_flux;
        self.chattering += usize::from(stats.chattering);
        self.sliding += usize::from(stats.sliding);
        self.grazing += usize::from(stats.grazing);
        self.grazing_error += stats.grazing_error;
        if let Some(point) = point {
            self.recent.push(point);
            if n >= self.first_kept {
                self.bifurcation.extend_from_slice(point);
            }
        }
        self.done += 1;
        self.uncertainty
            .end_iteration(self.qr.sums(), self.averaging_time());
        true
    }

    /// Goes on from the reference's points before the iterations this
    /// accumulator takes (the start's and the transient's): the result
    /// then has its convergence time.
    pub fn settle_from(&mut self, settling: Settling<D>) {
        self.settling = Some(settling);
    }

    /// The time of the averaging iterations so far: a Poincaré map's
    /// iterations' own times, or the map period's multiple.
    fn averaging_time(&self) -> f64 {
        if self.time > 0.0 {
            self.time
        } else {
            self.done as f64 * self.period
        }
    }

    /// The iterations taken so far, counted from the start of the transient:
    /// the index of the next one.
    fn taken(&self) -> usize {
        self.transient + self.aligned + self.done
    }

    /// Marks the lane failed at `iteration` (counted from the start of the transient).
    pub fn fail(&mut self, iteration: usize) {
        self.failed_at.get_or_insert(iteration);
    }

    /// Marks the lane failed at `iteration` for `cause` (the first
    /// failure stands).
    pub fn fail_because(&mut self, iteration: usize, cause: Failure) {
        if self.failed_at.is_none() {
            self.failure = cause;
        }
        self.fail(iteration);
    }

    /// Marks the lane failed at `iteration` on the non-finite point `x` of
    /// an iteration with the statistics `stats` ([`Failure::of`]).
    pub fn fail_at(&mut self, iteration: usize, x: &[f64], stats: &IterationStats) {
        self.fail_because(iteration, Failure::of(x, stats));
    }

    /// The lane's result after all its iterations.
    pub fn finish(mut self) -> LaneResult {
        // A Poincaré map's iterations take their own times: the period is
        // their mean, so that exponents are per unit of the total time.
        let orbit_term = if self.time > 0.0 {
            self.period = self.time / self.done.max(1) as f64;
            self.log_flux / self.time
        } else if self.log_flux != 0.0 {
            self.log_flux / (self.done.max(1) as f64 * self.period)
        } else {
            0.0
        };
        if let Some(iteration) = self.failed_at {
            return self.failed(iteration);
        }
        // With relative noise ε_n in the smallest R_ii, ln R_ii is biased by
        // about -ε_n²/2 and scattered by ε_n; over N Jacobians (iterations ×
        // parts) of time τ each that bounds the exponent error by
        // (⟨ε²⟩/2 + √(⟨ε²⟩/N)) / τ.
        let taken = self.parts_done.max(1) as f64;
        let part_time = if self.time > 0.0 {
            self.time / taken
        } else {
            self.period / self.plan.parts as f64
        };
        let mean_square = self.noise_squares / taken;
        let resolution_bound = (0.5 * mean_square + (mean_square / taken).sqrt()) / part_time;
        let averaging_time = self.averaging_time();
        let exponents = if self.lyapunov {
            self.frame_exponents(part_time, taken)
        } else {
            Vec::new()
        };
        let error = if self.lyapunov {
            self.uncertainty
                .error(self.qr.sums(), &exponents, self.rank_loss, averaging_time)
        } else {
            f64::NAN
        };
        let grazing_bound = self.grazing_error / (self.done.max(1) as f64 * self.period);
        let status = self.status(resolution_bound, grazing_bound);
        let orbit_period = self.recent.period();
        let orbit = self.recent.orbit(orbit_period);
        let settled = self.settling.as_ref().and_then(|s| {
            let periodic = orbit_period.map(|_| orbit.as_slice());
            s.time(periodic, self.done, self.settling_tolerance)
        });
        LaneResult {
            exponents,
            impacts_per_period: self.impacts as f64 / self.iterations as f64,
            crossings_per_period: self.crossings.map(|c| c as f64 / self.iterations as f64),
            period: self.period,
            orbit_period,
            orbit: if self.keep_orbit { orbit } else { Vec::new() },
            settled,
            orbit_term,
            bifurcation: self.bifurcation,
            jacobians: self.jacobians.unwrap_or_default(),
            grazing: self.grazing,
            grazing_bound,
            error,
            plan: self.plan,
            status,
        }
    }

    /// The result of a lane that failed at `iteration`: no numbers, the
    /// failure's status.
    fn failed(self, iteration: usize) -> LaneResult {
        LaneResult {
            exponents: if self.lyapunov {
                vec![f64::NAN; D]
            } else {
                Vec::new()
            },
            impacts_per_period: f64::NAN,
            crossings_per_period: [f64::NAN; MAX_EVENTS],
            period: self.period,
            orbit_period: None,
            orbit: Vec::new(),
            settled: None,
            orbit_term: f64::NAN,
            bifurcation: self.bifurcation,
            jacobians: self.jacobians.unwrap_or_default(),
            grazing: self.grazing,
            grazing_bound: f64::NAN,
            error: f64::NAN,
            plan: self.plan,
            status: match self.failure {
                Failure::NonFinite => LaneStatus::NonFinite { iteration },
                Failure::NoReturn => LaneStatus::NoReturn { iteration },
                Failure::TooManyEvents => LaneStatus::TooManyEvents { iteration },
            },
        }
    }

    /// The exponents of the QR frame, largest first, with the directions
    /// beyond the certain ones that sliding phases may have collapsed
    /// written as -∞.
    fn frame_exponents(&mut self, part_time: f64, taken: f64) -> Vec<f64> {
        let mut e = if self.time > 0.0 {
            self.qr.exponents_over(self.time)
        } else {
            self.qr.exponents(part_time)
        }
        .to_vec();
        e.sort_by(|a, b| b.total_cmp(a));
        // Directions beyond the certain ones that sliding phases may
        // have collapsed: collapsed where the finite differences saw
        // nothing in them above their own rounding, on average over
        // the Jacobians (a direction that contracts for real is kept
        // well above it by the sub-maps' plan, PART_NOISE).
        if self.noise.is_some() && self.parts_done > 0 {
            let floor = self.log_noise / taken + COLLAPSE_FLOOR.ln();
            while self.rank_loss < self.rank_loss_bound
                && e[D - 1 - self.rank_loss] * part_time < floor
            {
                self.rank_loss += 1;
            }
        }
        for x in &mut e[D - self.rank_loss..] {
            *x = f64::NEG_INFINITY;
        }
        e
    }

    /// The status of a lane that ran all its iterations: its first
    /// failing check, in the order the statuses rank.
    fn status(&self, resolution_bound: f64, grazing_bound: f64) -> LaneStatus {
        if self.chattering > 0 {
            LaneStatus::Chattering {
                iterations: self.chattering,
            }
        } else if self.sliding > 0 {
            LaneStatus::Sliding {
                iterations: self.sliding,
            }
        } else if resolution_bound > RESOLUTION_BOUND {
            LaneStatus::Unresolved {
                bound: resolution_bound,
            }
        } else if self.rank_loss > 0 && self.lyapunov {
            LaneStatus::Collapsed {
                exponents: self.rank_loss,
            }
        } else if grazing_bound > RESOLUTION_BOUND {
            LaneStatus::Grazing {
                iterations: self.grazing,
                bound: grazing_bound,
            }
        } else {
            LaneStatus::Ok
        }
    }
}

/// Whether every number of a point is finite.
pub(super) fn all_finite(x: &[f64]) -> bool {
    x.iter().all(|v| v.is_finite())
}
