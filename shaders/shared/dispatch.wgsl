// A dispatch's invocations numbered in one sequence. The host lays out a
// dispatch of more workgroups than one dimension holds (65 535 on most
// devices: 4.2 million invocations of 64) as rows of the device's width
// (`Dispatch::grid` in src/backend/gpu/pipeline.rs), so that a million lanes
// of five trajectories each are one batch. Invocations past the last row's
// end see an index past the work and return.
fn invocation_index(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.y * groups.x * WORKGROUP_SIZE + gid.x;
}
