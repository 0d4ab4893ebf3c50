//! Per-pass GPU times from timestamp queries.

/// GPU time of each named pass of one frame, in milliseconds, in the order the passes first
/// ran; passes that share a name are summed.
pub type PassTimes = Vec<(String, f64)>;

/// Hands out timestamp writes for the passes of a frame and reads their times back.
///
/// When the adapter has no timestamp queries, every method is a no-op and [`GpuTimer::read`]
/// returns an empty list, so callers need no special case.
pub struct GpuTimer {
    inner: Option<TimerInner>,
    names: Vec<String>,
}

struct TimerInner {
    query_set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    readback: wgpu::Buffer,
    period_ns: f64,
    max_passes: u32,
}

impl GpuTimer {
    /// A timer for up to `max_passes` passes a frame. `enabled` says whether the device was
    /// opened with `TIMESTAMP_QUERY`.
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, enabled: bool, max_passes: u32) -> Self {
        let inner = enabled.then(|| {
            let count = max_passes * 2;
            let bytes = u64::from(count) * 8;
            TimerInner {
                query_set: device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("pass timestamps"),
                    ty: wgpu::QueryType::Timestamp,
                    count,
                }),
                resolve: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("timestamp resolve"),
                    size: bytes,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
                readback: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("timestamp readback"),
                    size: bytes,
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }),
                period_ns: f64::from(queue.get_timestamp_period()),
                max_passes,
            }
        });
        Self {
            inner,
            names: Vec::new(),
        }
    }

    /// Whether times will be measured.
    pub fn enabled(&self) -> bool {
        self.inner.is_some()
    }

    /// Starts a new frame: forgets the passes of the last one.
    pub fn begin_frame(&mut self) {
        self.names.clear();
    }

    fn next_pair(&mut self, name: &str) -> Option<(&wgpu::QuerySet, u32)> {
        let inner = self.inner.as_ref()?;
        let index = self.names.len() as u32;
        if index >= inner.max_passes {
            return None;
        }
        self.names.push(name.to_owned());
        Some((&inner.query_set, index * 2))
    }

    /// Timestamp writes for a render pass called `name`.
    pub fn render_pass(&mut self, name: &str) -> Option<wgpu::RenderPassTimestampWrites<'_>> {
        self.next_pair(name)
            .map(|(query_set, i)| wgpu::RenderPassTimestampWrites {
                query_set,
                beginning_of_pass_write_index: Some(i),
                end_of_pass_write_index: Some(i + 1),
            })
    }

    /// Timestamp writes for a compute pass called `name`.
    pub fn compute_pass(&mut self, name: &str) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        self.next_pair(name)
            .map(|(query_set, i)| wgpu::ComputePassTimestampWrites {
                query_set,
                beginning_of_pass_write_index: Some(i),
                end_of_pass_write_index: Some(i + 1),
            })
    }

    /// Records the copy of this frame's timestamps into the readback buffer.
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        let Some(inner) = &self.inner else { return };
        if self.names.is_empty() {
            return;
        }
        let count = self.names.len() as u32 * 2;
        encoder.resolve_query_set(&inner.query_set, 0..count, &inner.resolve, 0);
        encoder.copy_buffer_to_buffer(&inner.resolve, 0, &inner.readback, 0, u64::from(count) * 8);
    }

    /// Waits for the frame's submission and returns each pass's GPU time in milliseconds.
    pub fn read(&self, device: &wgpu::Device) -> PassTimes {
        let Some(inner) = &self.inner else {
            return Vec::new();
        };
        if self.names.is_empty() {
            return Vec::new();
        }
        let bytes = self.names.len() as u64 * 16;
        let (tx, rx) = std::sync::mpsc::channel();
        inner
            .readback
            .map_async(wgpu::MapMode::Read, 0..bytes, move |r| {
                let _ = tx.send(r);
            });
        let _ = device.poll(wgpu::PollType::wait_indefinitely());
        let mapped = matches!(rx.recv(), Ok(Ok(())));
        if !mapped {
            return Vec::new();
        }
        let times = {
            let Ok(view) = inner.readback.get_mapped_range(0..bytes) else {
                inner.readback.unmap();
                return Vec::new();
            };
            let ticks: &[u64] = bytemuck::cast_slice(&view);
            // Passes of the same name (e.g. one per grass batch) are summed.
            let mut times: PassTimes = Vec::new();
            for (i, name) in self.names.iter().enumerate() {
                let (begin, end) = (ticks[i * 2], ticks[i * 2 + 1]);
                let ms = end.saturating_sub(begin) as f64 * inner.period_ns / 1e6;
                match times.iter_mut().find(|(n, _)| n == name) {
                    Some((_, t)) => *t += ms,
                    None => times.push((name.clone(), ms)),
                }
            }
            times
        };
        inner.readback.unmap();
        times
    }
}
