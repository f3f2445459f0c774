//! Records compute dispatches into the engine's encoder. Every SDK dispatch goes through
//! [`Recorder`], so GPU timing (timestamp queries around each pass) is one switch.

use bytemuck::Pod;

/// Largest workgroup count of one dispatch dimension (WebGPU default limit).
pub(crate) const MAX_DISPATCH_DIM: u32 = 65535;

/// Splits a 1-D workgroup count into `(x, y)` with `x ≤ 65535`. Shaders rebuild the linear index
/// as `wid.y * nwg.x + wid.x` and return past their element count.
pub(crate) fn split_workgroups(count: u32) -> (u32, u32) {
    if count <= MAX_DISPATCH_DIM {
        (count.max(1), 1)
    } else {
        let y = count.div_ceil(MAX_DISPATCH_DIM);
        (count.div_ceil(y), y)
    }
}

/// One timed pass: its label and the query indices of its begin/end timestamps.
#[derive(Debug, Clone)]
pub(crate) struct TimedPass {
    /// What the SDK was doing (the recorder's scope: "ingest", "blas build", …).
    pub scope: &'static str,
    /// The pass itself.
    pub label: &'static str,
    pub begin: u32,
    pub end: u32,
}

/// Timestamp queries of one GPU task (present only when GPU timing is enabled).
pub(crate) struct Timestamps {
    pub query_set: wgpu::QuerySet,
    pub capacity: u32,
    pub passes: Vec<TimedPass>,
}

impl Timestamps {
    /// Queries of one task: two per pass, the most one query set may hold (wgpu's limit).
    /// Passes past it go untimed: per-object passes (a task allocating the lighting caches of
    /// thousands of instances) can outnumber it.
    pub const CAPACITY: u32 = 4096;

    pub fn new(device: &wgpu::Device) -> Self {
        Timestamps {
            query_set: device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("kickstart-rt timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: Self::CAPACITY,
            }),
            capacity: Self::CAPACITY,
            passes: Vec::new(),
        }
    }

    /// The begin and end query indices of a new timed pass, `None` when the set is full.
    fn reserve(&mut self, scope: &'static str, label: &'static str) -> Option<(u32, u32)> {
        let begin = self.passes.len() as u32 * 2;
        if begin + 2 > self.capacity {
            return None;
        }
        self.passes.push(TimedPass {
            scope,
            label,
            begin,
            end: begin + 1,
        });
        Some((begin, begin + 1))
    }

    fn next(
        &mut self,
        scope: &'static str,
        label: &'static str,
    ) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        let (begin, end) = self.reserve(scope, label)?;
        Some(wgpu::ComputePassTimestampWrites {
            query_set: &self.query_set,
            beginning_of_pass_write_index: Some(begin),
            end_of_pass_write_index: Some(end),
        })
    }
}

/// Records compute work for one GPU task into the engine's encoder.
pub(crate) struct Recorder<'a> {
    pub device: &'a wgpu::Device,
    pub encoder: &'a mut wgpu::CommandEncoder,
    pub timestamps: Option<&'a mut Timestamps>,
    /// Attributes the following passes' timings ("ingest", "blas build", …).
    pub scope: &'static str,
    /// Compute passes recorded so far. The builds are designed around their count of dependent
    /// dispatches (each costs a gap on a large GPU), so tests assert it.
    pub dispatches: u32,
}

impl<'a> Recorder<'a> {
    /// A recorder without timing (unit tests; the context builds its recorders directly).
    #[cfg(test)]
    pub fn new(device: &'a wgpu::Device, encoder: &'a mut wgpu::CommandEncoder) -> Self {
        Recorder {
            device,
            encoder,
            timestamps: None,
            scope: "",
            dispatches: 0,
        }
    }

    /// Begins a compute pass named `label` (timed when GPU timing is on) with `pipeline` set:
    /// what every dispatch method starts with.
    fn begin_pass(
        &mut self,
        label: &'static str,
        pipeline: &wgpu::ComputePipeline,
    ) -> wgpu::ComputePass<'_> {
        self.dispatches += 1;
        let scope = self.scope;
        let timestamp_writes = self.timestamps.as_mut().and_then(|t| t.next(scope, label));
        let mut pass = self
            .encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(label),
                timestamp_writes,
            });
        pass.set_pipeline(pipeline);
        pass
    }

    /// One compute pass with one dispatch of `workgroups` (1-D, split into 2-D when large).
    /// `bind_groups[i]` binds to group `i`.
    pub fn dispatch(
        &mut self,
        label: &'static str,
        pipeline: &wgpu::ComputePipeline,
        bind_groups: &[&wgpu::BindGroup],
        workgroups: u32,
    ) {
        if workgroups == 0 {
            return;
        }
        let mut pass = self.begin_pass(label, pipeline);
        for (i, bg) in bind_groups.iter().enumerate() {
            pass.set_bind_group(i as u32, Some(*bg), &[]);
        }
        let (x, y) = split_workgroups(workgroups);
        pass.dispatch_workgroups(x, y, 1);
    }

    /// One compute pass with one 1-D dispatch per `(bind group 0, workgroups)` of `groups`, in
    /// order: many small independent dispatches (one per caller mesh) share one pass, so the GPU
    /// may overlap them and a timed frame writes one timestamp pair instead of one per dispatch
    /// (each pair makes the GPU drain). wgpu still orders dispatches that share a written buffer.
    pub fn dispatch_each(
        &mut self,
        label: &'static str,
        pipeline: &wgpu::ComputePipeline,
        groups: &[(wgpu::BindGroup, u32)],
    ) {
        if groups.iter().all(|(_, n)| *n == 0) {
            return;
        }
        let mut pass = self.begin_pass(label, pipeline);
        for (group, workgroups) in groups.iter().filter(|(_, n)| *n > 0) {
            pass.set_bind_group(0, Some(group), &[]);
            let (x, y) = split_workgroups(*workgroups);
            pass.dispatch_workgroups(x, y, 1);
        }
    }

    /// One compute pass with one 2-D dispatch of `(x, y)` workgroups (image passes).
    pub fn dispatch_2d(
        &mut self,
        label: &'static str,
        pipeline: &wgpu::ComputePipeline,
        bind_groups: &[&wgpu::BindGroup],
        (x, y): (u32, u32),
    ) {
        if x == 0 || y == 0 {
            return;
        }
        let mut pass = self.begin_pass(label, pipeline);
        for (i, bg) in bind_groups.iter().enumerate() {
            pass.set_bind_group(i as u32, Some(*bg), &[]);
        }
        pass.dispatch_workgroups(x, y, 1);
    }

    /// Encoder work that is not a compute pass (the driver's acceleration-structure builds),
    /// timed as a pass named `label` when GPU timing is on and the device can write timestamps
    /// between passes (`TIMESTAMP_QUERY_INSIDE_ENCODERS`); untimed otherwise.
    pub fn encoder_work(
        &mut self,
        label: &'static str,
        work: impl FnOnce(&mut wgpu::CommandEncoder),
    ) {
        let inside = self
            .device
            .features()
            .contains(wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS);
        let scope = self.scope;
        let queries = match self.timestamps.as_mut() {
            Some(t) if inside => t.reserve(scope, label).map(|q| (&t.query_set, q)),
            _ => None,
        };
        match queries {
            Some((set, (begin, end))) => {
                self.encoder.write_timestamp(set, begin);
                work(self.encoder);
                self.encoder.write_timestamp(set, end);
            }
            None => work(self.encoder),
        }
    }

    /// A uniform buffer holding `data` (written at creation: safe to use in this encoder).
    pub fn uniform<T: Pod>(&self, label: &str, data: &T) -> wgpu::Buffer {
        crate::gpu::buffers::buffer_init(
            self.device,
            label,
            bytemuck::bytes_of(data),
            wgpu::BufferUsages::UNIFORM,
        )
    }

    /// A storage buffer initialised with `data` (read-only use; written at creation).
    pub fn storage_init(&self, label: &str, data: &[u8]) -> wgpu::Buffer {
        let mut padded;
        let contents = if !data.len().is_multiple_of(4) || data.is_empty() {
            padded = data.to_vec();
            padded.resize(data.len().div_ceil(4).max(1) * 4, 0);
            &padded[..]
        } else {
            data
        };
        crate::gpu::buffers::buffer_init(
            self.device,
            label,
            contents,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn workgroup_split_covers_the_count_within_limits() {
        for n in [1u32, 65535, 65536, 200_000, 16_000_000] {
            let (x, y) = split_workgroups(n);
            assert!(x <= MAX_DISPATCH_DIM && y <= MAX_DISPATCH_DIM);
            assert!(x as u64 * y as u64 >= n as u64, "{n}: {x}x{y}");
        }
    }
}
