#ifdef SURFACES
// ---- General surfaces: twins of src/integrate/surface.rs and of the
// surface branch of resolve and cross in src/integrate/impact/. The
// system file gives SURFACES, each one's SURFACE_BIT (EVENT for an event),
// surface_g, surface_values (g and the rate ∇g·F + ∂g/∂t along the field
// of p.region), surface_gradient and reset. A trajectory's field is that
// of its region, p.region: rhs reads a switch's side from it, never from
// the state. Regions, the stop test over every surface, a switch's sides,
// the sliding field, the slide and a crossing (cross) are generated from
// the step program (src/model/ir/surfaces.rs), and ln |det S| of an
// event's crossing; here are what they read of the kernels (the region's
// layout) and a crossing's effect on the step loop's Resolution and on
// `crossed`.

// What resolve_impacts did to the surfaces in its step, beside its
// WallStep: the region it ends in, Σ ln |det S| of its crossings, and
// whether one could not be resolved (sliding). Set by the integrate kernel
// before the call, read after it.
struct Crossed {
    region: u32,
    log_flux: real,
    sliding: bool,
    // Sliding phases entered (IterationStats::sliding_phases).
    sliding_phases: u32,
}
var<private> crossed: Crossed;

// Region bits from SLIDING_SHIFT up mark a motion sliding on surface j
// (bit SLIDING_SHIFT + j), the bits below are the sides (surface::SLIDING).
const SLIDING_SHIFT: u32 = 16u;
const SIDES: u32 = 0xffffu;

// General surface met.stop - WALLS crossed at met.hit (the surface branch
// of resolve): the crossing applied, counted and, in `crossed`, its region,
// ln |det S| and flags; the rest of the step is stepped again unless the
// motion now slides (resolve_impacts' next pass slides it).
fn cross_surface(p: Params, omega: real, met: Met, r_in: Resolution) -> Resolution {
    var r = r_in;
    let phase_c = rotate(r.phase0, cos_sin(omega * met.hit.s));
    r.done = r.done + met.hit.s;
    let crossing = cross(p, met.stop - WALLS, phase_c, met.hit.y);
    r.slowest = min(r.slowest, crossing.approach);
    if (crossing.counted) {
        r.crossings[met.stop] = r.crossings[met.stop] + 1u;
    }
    if (crossing.rank_loss) {
        r.rank_loss = max(r.rank_loss, 1u);
    }
    crossed.region = crossing.region;
    crossed.log_flux = crossed.log_flux + crossing.log_det;
    crossed.sliding = crossed.sliding || crossing.sliding;
    r.phase0 = phase_c;
    if (!crossing.resolved) {
        // Flagged: the rest of the step in the field now in force, and the
        // step ends there.
        r.y0 = met.hit.y;
        r.restep = true;
        r.unresolved = true;
        r.chattering = crossing.chattering;
        return r;
    }
    if (crossing.slides) {
        crossed.sliding_phases = crossed.sliding_phases + 1u;
    }
    r.y0 = crossing.y;
    r.restep = !is_sliding(crossing.region);
    return r;
}
#endif
