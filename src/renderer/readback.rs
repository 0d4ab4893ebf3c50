//! The frame's figures on their way back from the GPU: a small ring of readback buffers, each
//! mapped when its frame's encoder is submitted and read once mapped, never waited for.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};

use super::{FrameStats, MAX_READY_STATS, READBACK_SLOTS};
use crate::gpu::GpuTimer;
use crate::grass::GrassStats;

use crate::plants::renderer::{ARGS_BYTES, STATS_BYTES};

/// Where the plant layers' figures start in a slot after the timestamps: after the grass's
/// counters (64 bytes) and the hole check's (16), each layer's counters ([`STATS_BYTES`]), then
/// each layer's draw arguments.
const PLANTS_AT: u64 = 64 + 16;

const FREE: u8 = 0;
const PENDING: u8 = 1;
const MAPPED: u8 = 2;
const FAILED: u8 = 3;
/// The slot's encoder was dropped without being submitted: its map callback was dropped
/// uncalled, and the buffer was never mapped.
const ABANDONED: u8 = 4;

/// The end of a slot's wait, carried by its map callback: the mapping's result where the
/// callback runs, or, where wgpu drops the callback uncalled (the encoder, or its command
/// buffer, dropped without being submitted), [`ABANDONED`], so that the slot is not waited for
/// forever.
struct Settle {
    state: Arc<AtomicU8>,
    settled: bool,
}

impl Settle {
    fn settle(mut self, mapped: bool) {
        let state = if mapped { MAPPED } else { FAILED };
        self.state.store(state, Ordering::Release);
        self.settled = true;
    }
}

impl Drop for Settle {
    fn drop(&mut self) {
        if !self.settled {
            self.state.store(ABANDONED, Ordering::Release);
        }
    }
}

/// One frame's figures on their way back: a buffer mapped on submit, and what the CPU knew.
struct ReadbackSlot {
    buffer: wgpu::Buffer,
    state: Arc<AtomicU8>,
    frame: Option<(FrameStats, Vec<String>)>,
}

/// A small ring of readback buffers: each frame copies its timestamps and grass counters into
/// a free slot, mapped when the encoder is submitted; figures are read once mapped, a frame or
/// two later, and never waited for.
pub(super) struct StatsRing {
    slots: Vec<ReadbackSlot>,
    timestamp_bytes: u64,
    pub(super) ready: VecDeque<FrameStats>,
    /// The newest of the figures last taken from `ready`: the newest to come back while
    /// `ready` is empty.
    pub(super) taken_last: Option<FrameStats>,
    pub(super) dropped: u64,
}

impl StatsRing {
    pub(super) fn new(device: &wgpu::Device, timestamp_bytes: u64) -> Self {
        let slots = (0..READBACK_SLOTS)
            .map(|_| ReadbackSlot {
                buffer: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("frame figures readback"),
                    size: timestamp_bytes + PLANTS_AT + 2 * (STATS_BYTES + ARGS_BYTES),
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }),
                state: Arc::new(AtomicU8::new(FREE)),
                frame: None,
            })
            .collect();
        Self {
            slots,
            timestamp_bytes,
            ready: VecDeque::with_capacity(MAX_READY_STATS + 1),
            taken_last: None,
            dropped: 0,
        }
    }

    pub(super) fn record(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        timer: &GpuTimer,
        counters: Option<&wgpu::Buffer>,
        holes: &wgpu::Buffer,
        plants: [Option<(&wgpu::Buffer, &wgpu::Buffer)>; 2],
        stats: FrameStats,
    ) {
        let Some(slot) = self
            .slots
            .iter_mut()
            .find(|s| s.state.load(Ordering::Acquire) == FREE)
        else {
            self.dropped += 1;
            return;
        };
        let names = timer.names().to_vec();
        if let Some(resolve) = timer.resolve_buffer()
            && !names.is_empty()
        {
            encoder.copy_buffer_to_buffer(resolve, 0, &slot.buffer, 0, names.len() as u64 * 16);
        }
        if let Some(c) = counters {
            encoder.copy_buffer_to_buffer(c, 0, &slot.buffer, self.timestamp_bytes, 64);
        }
        encoder.copy_buffer_to_buffer(holes, 0, &slot.buffer, self.timestamp_bytes + 64, 16);
        // The plants' counters and draws, then the trees'.
        for (k, p) in plants.into_iter().enumerate() {
            if let Some((counters, args)) = p {
                let at = self.timestamp_bytes + PLANTS_AT + STATS_BYTES * k as u64;
                encoder.copy_buffer_to_buffer(counters, 0, &slot.buffer, at, STATS_BYTES);
                let at = self.timestamp_bytes + PLANTS_AT + 2 * STATS_BYTES + ARGS_BYTES * k as u64;
                encoder.copy_buffer_to_buffer(args, 0, &slot.buffer, at, ARGS_BYTES);
            }
        }
        slot.state.store(PENDING, Ordering::Release);
        let settle = Settle {
            state: slot.state.clone(),
            settled: false,
        };
        encoder.map_buffer_on_submit(&slot.buffer, wgpu::MapMode::Read, .., move |r| {
            settle.settle(r.is_ok());
        });
        slot.frame = Some((stats, names));
    }

    pub(super) fn collect(&mut self, timer: &GpuTimer) {
        let mut done: Vec<FrameStats> = Vec::new();
        for slot in &mut self.slots {
            match slot.state.load(Ordering::Acquire) {
                MAPPED => {
                    let (mut stats, names) = slot.frame.take().unwrap_or_default();
                    if let Ok(view) = slot.buffer.get_mapped_range(..) {
                        let words: &[u64] = bytemuck::cast_slice(&view);
                        let ticks = &words[..(self.timestamp_bytes / 8) as usize];
                        stats.gpu = timer.times(&names, ticks);
                        let counters: &[u32] =
                            bytemuck::cast_slice(&view[self.timestamp_bytes as usize..]);
                        let c: [u32; 16] = counters[..16].try_into().unwrap_or([0; 16]);
                        stats.grass = GrassStats::from_counts(stats.grass.tiles, &c);
                        // Atlas reads that found another tile than expected (HoleCheck).
                        stats.residency.holes += counters.get(16).copied().unwrap_or(0);
                        let read = |k: usize| {
                            const N: usize = STATS_BYTES as usize / 4;
                            let at = PLANTS_AT as usize / 4 + N * k;
                            let p: [u32; N] = counters
                                .get(at..at + N)
                                .and_then(|p| p.try_into().ok())
                                .unwrap_or([0; N]);
                            let words = ARGS_BYTES as usize / 4;
                            let at = PLANTS_AT as usize / 4 + 2 * N + words * k;
                            let args = counters.get(at..at + words).unwrap_or(&[]);
                            crate::plants::PlantStats::from_counts(&p).with_draws(args)
                        };
                        if stats.plants.is_some() {
                            stats.plants = Some(read(0));
                        }
                        if stats.trees.is_some() {
                            stats.trees = Some(read(1));
                        }
                    }
                    slot.buffer.unmap();
                    slot.state.store(FREE, Ordering::Release);
                    done.push(stats);
                }
                FAILED => {
                    slot.frame = None;
                    slot.buffer.unmap();
                    slot.state.store(FREE, Ordering::Release);
                    self.dropped += 1;
                }
                ABANDONED => {
                    slot.frame = None;
                    slot.state.store(FREE, Ordering::Release);
                    self.dropped += 1;
                }
                _ => {}
            }
        }
        done.sort_by_key(|s| s.frame);
        for s in done {
            if self.ready.len() == MAX_READY_STATS {
                self.ready.pop_front();
                self.dropped += 1;
            }
            self.ready.push_back(s);
        }
    }
}
