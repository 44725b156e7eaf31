//! GPU timestamp queries around compute passes, where the adapter has them
//! (`Features::TIMESTAMP_QUERY`): the time the device itself spent, free of
//! host scheduling, mapping and QR.
//!
//! Each pass writes a begin and an end timestamp into its own slot of a
//! small query set; the slot is resolved and copied into a buffer the host
//! reads anyway (the averaging chunk's staging buffer), so the measurement
//! costs no extra synchronisation.

use std::time::Duration;

use super::context::Gpu;

/// Slots: one per staging buffer of the averaging phase, one for the transient.
pub const SLOTS: u32 = 3;
pub const TRANSIENT_SLOT: u32 = 2;
/// Bytes a slot's two resolved timestamps take in a destination buffer.
pub const TICKS_BYTES: u64 = 16;

pub struct Stopwatch {
    queries: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    /// Nanoseconds per timestamp tick.
    period_ns: f64,
}

impl Stopwatch {
    /// `None` when the device was opened without timestamp queries.
    pub fn new(gpu: &Gpu) -> Option<Self> {
        if !gpu
            .device
            .features()
            .contains(wgpu::Features::TIMESTAMP_QUERY)
        {
            return None;
        }
        let queries = gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("pass timestamps"),
            ty: wgpu::QueryType::Timestamp,
            count: 2 * SLOTS,
        });
        let resolved = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("resolved timestamps"),
            size: u64::from(SLOTS) * wgpu::QUERY_RESOLVE_BUFFER_ALIGNMENT,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        Some(Stopwatch {
            queries,
            resolved,
            period_ns: f64::from(gpu.queue.get_timestamp_period()),
        })
    }

    /// The timestamp writes for a pass measured in `slot`.
    pub fn writes(&self, slot: u32) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: Some(2 * slot),
            end_of_pass_write_index: Some(2 * slot + 1),
        }
    }

    /// After the pass: resolves `slot` and copies its two ticks
    /// (`TICKS_BYTES`) into `destination` at `offset`.
    pub fn copy_out(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        slot: u32,
        destination: &wgpu::Buffer,
        offset: u64,
    ) {
        let at = u64::from(slot) * wgpu::QUERY_RESOLVE_BUFFER_ALIGNMENT;
        encoder.resolve_query_set(&self.queries, 2 * slot..2 * slot + 2, &self.resolved, at);
        encoder.copy_buffer_to_buffer(&self.resolved, at, destination, offset, TICKS_BYTES);
    }

    /// The time between the two ticks in `bytes` (as `copy_out` wrote them).
    pub fn elapsed(&self, bytes: &[u8]) -> Duration {
        let ticks = bytemuck::pod_read_unaligned::<[u64; 2]>(&bytes[..TICKS_BYTES as usize]);
        Duration::from_secs_f64(ticks[1].saturating_sub(ticks[0]) as f64 * self.period_ns * 1e-9)
    }
}
