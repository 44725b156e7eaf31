//! The kernels' binding layout, stated once: the uniform control structs
//! the host writes (`#[repr(C)]`, `Pod`, as vello states its encoding's
//! layout), the storage buffers it binds, and the strides and codes both
//! sides read. The host builds its bind group layouts and bind groups from
//! these tables, and `shader` writes their WGSL (the structs, the
//! `@binding` declarations, the constants) into each kernel's generated
//! prelude: the kernels' own files declare none of them.

use std::collections::BTreeSet;
use std::fmt::Write;

use crate::system::SystemInfo;

/// A uniform struct of `u32`s: the Rust type the host fills, and its WGSL
/// declaration under the name the kernels read it by.
macro_rules! control_struct {
    ($(#[$meta:meta])* $name:ident => $wgsl:ident {
        $($(#[$field_meta:meta])* $field:ident,)*
    }) => {
        $(#[$meta])*
        #[repr(C)]
        #[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
        pub struct $name {
            $($(#[$field_meta])* pub $field: u32,)*
        }

        impl $name {
            /// Each field's name and offset in the Rust struct.
            #[cfg(test)]
            const FIELDS: &'static [(&'static str, usize)] =
                &[$((stringify!($field), std::mem::offset_of!($name, $field))),*];

            /// The struct's WGSL declaration.
            pub const WGSL: &'static str = concat!(
                "struct ", stringify!($wgsl), " {\n",
                $("    ", stringify!($field), ": u32,\n",)*
                "}\n"
            );
        }

        // A uniform buffer's size is a multiple of 16 bytes.
        const _: () = assert!(std::mem::size_of::<$name>() % 16 == 0);
    };
}

/// `u32` constants both sides read: Rust constants, and the list their
/// WGSL declarations are written from.
macro_rules! shared_constants {
    ($list:ident: $($(#[$meta:meta])* $name:ident = $value:expr;)*) => {
        $($(#[$meta])* pub const $name: u32 = $value;)*
        const $list: &[(&str, u32)] = &[$((stringify!($name), $name)),*];
    };
}

control_struct! {
    /// The period map's kernels' control (integrate.wgsl, finish.wgsl).
    SweepControl => Control {
        /// Lanes in this batch.
        lane_count,
        /// RK4 steps per map period (1 for a map): parts × part_steps.
        steps_per_period,
        /// RK4 steps per integrate dispatch, bounding each dispatch's work.
        chunk_steps,
        /// 1 while discarding the transient: references only, nothing
        /// recorded.
        transient,
        /// Iteration slots in the output ring.
        ring,
        /// Always 0. Compensated (Kahan) sums must not be simplified
        /// algebraically, and WGSL cannot mark them exact (SPIR-V
        /// NoContraction): a select on a value the compiler cannot know
        /// hides the identity (y + c) - y = c.
        opaque_zero,
        /// While averaging, each iteration is cut into `parts` sub-maps of
        /// `part_steps` steps (see system::Part): at the end of each, the
        /// finish kernel takes the part's Jacobian and re-seeds the copies
        /// from the reference, which runs on. One part is the whole
        /// iteration.
        part_steps,
        parts,
    }
}

control_struct! {
    /// A Poincaré map's kernel's control (section.wgsl).
    SectionControl => Control {
        /// Jobs in this round.
        job_count,
        chunk_steps,
        /// Always 0 (see `SweepControl::opaque_zero`).
        opaque_zero,
        pad,
    }
}

shared_constants! {
    SWEEP_FLAGS:
    // counts[t].z and a summary's .y: what happened to a trajectory and
    // its lane's part of an iteration.
    /// Impacts piled up in the iteration (chattering).
    FLAG_CHATTERING = 1;
    FLAG_NONFINITE = 2;
    /// The iteration collapsed one dimension (an impact with e = 0), or two
    /// (sticking: the mass's position and velocity; all of them with two
    /// states): see IterationStats::rank_loss.
    FLAG_RANK_ONE = 4;
    FLAG_RANK_TWO = 8;
    /// The adapter cut this dispatch's loops short
    /// (loop_budget_exhausted): the host redoes the batch with shorter
    /// dispatches.
    FLAG_TRUNCATED = 16;
    /// A copy seeded behind the wall (its reference within δ of it): its
    /// column is differenced on the other side (System::admits on the CPU).
    FLAG_BEHIND_WALL = 32;
    /// A motion on a switch the kernels do not integrate (another surface
    /// met while sliding, a switch left against its new field, or no
    /// Filippov combination): IterationStats::sliding; the backend
    /// recomputes the lane on the CPU.
    FLAG_SLIDING = 64;
    /// A trajectory met more located events in the part than
    /// MAX_EVENTS_PER_ITERATION and was ended there, non-finite:
    /// IterationStats::too_many_events (kept with FLAG_NONFINITE).
    FLAG_TOO_MANY_EVENTS = 128;
}

shared_constants! {
    SECTION_MODES:
    // A section job's mode, jobs[j].y.
    DONE = 0;
    ADVANCE = 1;
    SEEK = 2;
    CROSSED = 3;
    MISSED = 4;
    /// Set (with the mode kept) when the adapter cut a dispatch's loops
    /// short: that dispatch stored nothing, and the host shortens the next
    /// ones.
    TRUNCATED = 0x100;
}

/// How a kernel reads a binding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Access {
    Uniform,
    Read,
    ReadWrite,
}

/// One binding of group 0.
#[derive(Clone, Copy, Debug)]
pub struct Binding {
    pub index: u32,
    /// The variable's name in the kernels, and the host's label for it.
    pub name: &'static str,
    /// Its WGSL type.
    pub ty: &'static str,
    pub access: Access,
    /// The define (`Variant::defines`) without which the variant has no
    /// such binding.
    pub when: Option<&'static str>,
}

const fn binding(index: u32, name: &'static str, ty: &'static str, access: Access) -> Binding {
    Binding {
        index,
        name,
        ty,
        access,
        when: None,
    }
}

const fn only(define: &'static str, b: Binding) -> Binding {
    Binding {
        when: Some(define),
        ..b
    }
}

/// A schedule's bindings, control struct and constants.
pub struct Bindings {
    pub label: &'static str,
    control: &'static str,
    constants: &'static [(&'static str, u32)],
    bindings: &'static [Binding],
    /// The strides of the buffers a variant's lanes fill, by its system
    /// and its defines (`Variant::defines`).
    strides: fn(&SystemInfo, &BTreeSet<&str>) -> Strides,
}

/// Reals per lane and per trajectory, and `vec4<u32>`s of summary per
/// ring slot (0 where a schedule has no such buffer).
#[derive(Clone, Copy, Debug)]
pub struct Strides {
    pub lane: usize,
    pub traj: usize,
    pub summary: usize,
}

/// The period map's kernels. A lane is one parameter value; it owns TRAJ
/// trajectories (the reference, then the copies at x + δe_i, then for
/// central differences those at x - δe_i, when exponents are wanted),
/// stored lane-major so a lane's trajectories sit side by side and take
/// the same branches (impacts) together.
pub const SWEEP: Bindings = Bindings {
    label: "sweep",
    control: SweepControl::WGSL,
    constants: SWEEP_FLAGS,
    bindings: &[
        binding(0, "control", "Control", Access::Uniform),
        // Per lane (LANE_STRIDE): the system's parameters, then h,
        // cos(ωh/2), sin(ωh/2), ω, δ.
        binding(1, "lanes", "array<real>", Access::Read),
        // Per trajectory (TRAJ_STRIDE): y (DIM), the compensation of y
        // (DIM), the phase (2), the slowest impact speed of the iteration
        // so far; with general surfaces, then its region of the switches
        // and the part's Σ ln |det S| (bindings.wgsl's TRAJ_*).
        binding(2, "traj", "array<real>", Access::ReadWrite),
        // Per trajectory: (step within the period, impacts this iteration,
        // flags, iteration).
        binding(3, "counts", "array<vec4<u32>>", Access::ReadWrite),
        // Per ring slot and lane, a slot per part of an iteration:
        // (impacts, flags, bits of the f32 max |y|, bits of the f32
        // nonlinearity), then with stops the impacts on each
        // (SUMMARY_STRIDE vectors per slot).
        binding(4, "summary", "array<vec4<u32>>", Access::ReadWrite),
        // Per lane: the perturbation actually taken per copy,
        // (x_i + δ) - x_i (then x_i - (x_i - δ) for central differences).
        only(
            "LYAPUNOV",
            binding(5, "deltas", "array<real>", Access::ReadWrite),
        ),
        // Per ring slot (a part of an iteration) and lane: the estimated
        // Jacobian, row-major.
        only(
            "LYAPUNOV",
            binding(6, "jac", "array<real>", Access::ReadWrite),
        ),
        // Per ring slot (a part of an iteration) and lane: the reference's
        // state at the part's end; the last part's is the Poincaré point
        // (the host's orbit periods, bifurcation points and grazing
        // re-estimates start from it).
        binding(7, "points", "array<real>", Access::ReadWrite),
        // Per trajectory: its impacts on each stop in the current part of
        // an iteration (components past WALLS stay 0); counts[t].y is
        // their sum.
        only(
            "WALL",
            binding(8, "crossings", "array<vec4<u32>>", Access::ReadWrite),
        ),
        // Per ring slot and lane: the reference's Σ ln |det S| over the
        // part's crossings of general surfaces (IterationStats::log_flux).
        only(
            "SURFACES",
            binding(9, "fluxes", "array<real>", Access::ReadWrite),
        ),
    ],
    strides: |system, defines| Strides {
        lane: system.parameters.len() + 5,
        // With surfaces, each trajectory's region and flux follow.
        traj: 2 * system.dimension() + 3 + 2 * usize::from(defines.contains("SURFACES")),
        // With stops, the impacts on each follow the summary.
        summary: 1 + usize::from(defines.contains("WALL")),
    },
};

/// A Poincaré map's kernel: one job per trajectory per round.
pub const SECTION: Bindings = Bindings {
    label: "section",
    control: SectionControl::WGSL,
    constants: SECTION_MODES,
    bindings: &[
        binding(0, "control", "Control", Access::Uniform),
        // Per lane (LANE_STRIDE): the system's parameters, then the
        // section's `at`.
        binding(1, "lanes", "array<real>", Access::Read),
        // Per job: (lane, mode, limit, steps taken).
        binding(2, "jobs", "array<vec4<u32>>", Access::ReadWrite),
        // Per job: its step h.
        binding(3, "steps", "array<real>", Access::Read),
        // Per job: the state (DIM), then for a crossing the state after
        // the crossing step (DIM); in f32, until then, the state's
        // compensation.
        binding(4, "states", "array<real>", Access::ReadWrite),
    ],
    strides: |system, _| Strides {
        lane: system.parameters.len() + 1,
        traj: 0,
        summary: 0,
    },
};

impl Bindings {
    /// The bindings of a variant with `defines`.
    fn present<'a>(&'a self, defines: &'a BTreeSet<&str>) -> impl Iterator<Item = &'a Binding> {
        self.bindings
            .iter()
            .filter(|b| b.when.is_none_or(|d| defines.contains(d)))
    }

    /// The strides of a variant of `system` with `defines`.
    pub fn strides(&self, system: &SystemInfo, defines: &BTreeSet<&str>) -> Strides {
        (self.strides)(system, defines)
    }

    /// The bind group layout's entries of a variant with `defines`.
    pub fn layout_entries(&self, defines: &BTreeSet<&str>) -> Vec<wgpu::BindGroupLayoutEntry> {
        self.present(defines)
            .map(|b| {
                let ty = match b.access {
                    Access::Uniform => wgpu::BufferBindingType::Uniform,
                    Access::Read => wgpu::BufferBindingType::Storage { read_only: true },
                    Access::ReadWrite => wgpu::BufferBindingType::Storage { read_only: false },
                };
                wgpu::BindGroupLayoutEntry {
                    binding: b.index,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                }
            })
            .collect()
    }

    /// The bind group of a variant with `defines` over `layout`, each
    /// binding bound to `buffer(name)`.
    pub fn bind_group<'b>(
        &self,
        device: &wgpu::Device,
        layout: &wgpu::BindGroupLayout,
        defines: &BTreeSet<&str>,
        buffer: impl Fn(&str) -> Option<&'b wgpu::Buffer>,
    ) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = self
            .present(defines)
            .map(|b| wgpu::BindGroupEntry {
                binding: b.index,
                resource: buffer(b.name)
                    .unwrap_or_else(|| panic!("no buffer for binding {}", b.name))
                    .as_entire_binding(),
            })
            .collect();
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(self.label),
            layout,
            entries: &entries,
        })
    }

    /// The layout's WGSL for a variant of `system` with `defines`: the
    /// control struct, the workgroup size, the strides and constants, and
    /// the bindings it has.
    pub fn wgsl(&self, system: &SystemInfo, defines: &BTreeSet<&str>) -> String {
        let strides = self.strides(system, defines);
        let mut out = String::from(self.control);
        // Set by the host when it builds the pipeline (the benchmark
        // measures several sizes).
        out.push_str("override WORKGROUP_SIZE: u32 = 64u;\n");
        let mut constant = |name: &str, value: usize| {
            writeln!(out, "const {name}: u32 = {value}u;").expect("a String takes text")
        };
        constant("LANE_STRIDE", strides.lane);
        if strides.traj > 0 {
            constant("TRAJ_STRIDE", strides.traj);
            constant("SUMMARY_STRIDE", strides.summary);
        }
        for &(name, value) in self.constants {
            constant(name, value as usize);
        }
        for b in self.present(defines) {
            let space = match b.access {
                Access::Uniform => "uniform",
                Access::Read => "storage, read",
                Access::ReadWrite => "storage, read_write",
            };
            writeln!(
                out,
                "@group(0) @binding({}) var<{space}> {}: {};",
                b.index, b.name, b.ty
            )
            .expect("a String takes text");
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The WGSL struct the kernels read has the Rust struct's fields at
    /// the same offsets, and its size: WGSL's uniform layout and
    /// `repr(C)` agree.
    #[test]
    fn each_control_struct_lies_in_wgsl_as_in_rust() {
        let structs = [
            (
                SweepControl::WGSL,
                SweepControl::FIELDS,
                std::mem::size_of::<SweepControl>(),
            ),
            (
                SectionControl::WGSL,
                SectionControl::FIELDS,
                std::mem::size_of::<SectionControl>(),
            ),
        ];
        for (wgsl, fields, size) in structs {
            let source = format!("{wgsl}@group(0) @binding(0) var<uniform> control: Control;\n");
            let module = naga::front::wgsl::parse_str(&source).expect("valid WGSL");
            let (_, ty) = module
                .types
                .iter()
                .find(|(_, t)| t.name.as_deref() == Some("Control"))
                .expect("the struct Control");
            let naga::TypeInner::Struct { members, span } = &ty.inner else {
                panic!("Control is a struct");
            };
            let offsets: Vec<(&str, usize)> = members
                .iter()
                .map(|m| (m.name.as_deref().unwrap_or(""), m.offset as usize))
                .collect();
            assert_eq!(offsets, fields, "{wgsl}");
            assert_eq!(*span as usize, size, "{wgsl}");
        }
    }
}
