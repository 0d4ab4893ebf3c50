//! Per-pass GPU times from timestamp queries.

/// GPU time of each named pass of one frame, in milliseconds, in the order the passes first
/// ran; passes that share a name are summed.
pub type PassTimes = Vec<(String, f64)>;

/// Hands out timestamp writes for the passes of a frame and resolves them into a buffer, from
/// which the caller copies them out ([`GpuTimer::resolve_buffer`]; the renderer copies them
/// into its readback ring) and turns the ticks into times ([`GpuTimer::times`]).
///
/// When the adapter has no timestamp queries, every method is a no-op and there is nothing to
/// read, so callers need no special case.
pub struct GpuTimer {
    inner: Option<TimerInner>,
    names: Vec<String>,
    /// Passes of this frame that asked for timestamps beyond the timer's room.
    untimed: u32,
    /// Whether the log has said that passes went untimed.
    warned: bool,
}

struct TimerInner {
    query_set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
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
                period_ns: f64::from(queue.get_timestamp_period()),
                max_passes,
            }
        });
        Self {
            inner,
            names: Vec::new(),
            untimed: 0,
            warned: false,
        }
    }

    /// Whether times will be measured.
    pub fn enabled(&self) -> bool {
        self.inner.is_some()
    }

    /// Starts a new frame: forgets the passes of the last one.
    pub fn begin_frame(&mut self) {
        self.names.clear();
        self.untimed = 0;
    }

    /// How many passes of this frame asked for timestamps when the timer had no room left:
    /// their time is missing from [`Self::times`], so the frame's sum falls short of it.
    pub fn untimed(&self) -> u32 {
        self.untimed
    }

    fn next_pair(&mut self, name: &str) -> Option<(&wgpu::QuerySet, u32)> {
        let inner = self.inner.as_ref()?;
        let index = self.names.len() as u32;
        if index >= inner.max_passes {
            if !self.warned {
                log::warn!(
                    "GPU timing: pass {name:?} and those after it go untimed, past the {} a frame has room for",
                    inner.max_passes
                );
                self.warned = true;
            }
            self.untimed += 1;
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

    /// Records the resolution of this frame's timestamps into [`Self::resolve_buffer`]: 16
    /// bytes (begin and end ticks) per pass of [`Self::names`].
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        let Some(inner) = &self.inner else { return };
        if self.names.is_empty() {
            return;
        }
        let count = self.names.len() as u32 * 2;
        encoder.resolve_query_set(&inner.query_set, 0..count, &inner.resolve, 0);
    }

    /// The buffer the timestamps are resolved into (`COPY_SRC`), when timing is on.
    pub fn resolve_buffer(&self) -> Option<&wgpu::Buffer> {
        self.inner.as_ref().map(|i| &i.resolve)
    }

    /// Bytes of the resolve buffer: room for every pass the timer can time.
    pub fn capacity_bytes(&self) -> u64 {
        self.inner
            .as_ref()
            .map_or(0, |i| u64::from(i.max_passes) * 16)
    }

    /// The passes timed this frame, in order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Each pass's GPU time in milliseconds from the resolved `ticks` (two per name), passes of
    /// the same name (one per grass batch, say) summed, in the order they first ran.
    pub fn times(&self, names: &[String], ticks: &[u64]) -> PassTimes {
        let Some(inner) = &self.inner else {
            return Vec::new();
        };
        let mut times: PassTimes = Vec::new();
        for (i, name) in names.iter().enumerate() {
            let (Some(&begin), Some(&end)) = (ticks.get(i * 2), ticks.get(i * 2 + 1)) else {
                break;
            };
            let ms = end.saturating_sub(begin) as f64 * inner.period_ns / 1e6;
            match times.iter_mut().find(|(n, _)| n == name) {
                Some((_, t)) => *t += ms,
                None => times.push((name.clone(), ms)),
            }
        }
        times
    }
}
