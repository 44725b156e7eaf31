// Reads the kernel's `control` uniform (its `opaque_zero`), which every
// kernel's generated prelude declares (src/backend/gpu/bindings.rs).

// lavapipe (Mesa's gallivm) caps the loop iterations of one shader
// invocation at 65 535, counted over all its loops together and shared by
// the lanes of a SIMD group; past the cap every loop stops after one pass,
// silently. A chattering lane, or a long dispatch of steps with impacts,
// reached it and came out wrong. A loop of two passes, bounded by a uniform
// so that it cannot be unrolled, tells whether this invocation stayed
// within the cap.
fn loop_budget_exhausted() -> bool {
    var passes = 0u;
    for (var i = 0u; i < 2u + control.opaque_zero; i = i + 1u) {
        passes = passes + 1u;
    }
    return passes < 2u;
}
