//! The raw geometry copy of a task's ingestions: every byte range the ingestions read from the
//! user's buffers (vertices, indices, opacity sources) is copied into one buffer, which the
//! ingestion passes bind. Ranges of one buffer that overlap or lie close together are copied
//! once, as one range: meshes posed into one pooled buffer, or sharing one index buffer, cost one
//! copy command, not one each (every copy command has a fixed cost on the GPU, whatever its
//! size), and shared bytes are copied once.

/// Ranges of one buffer at most this far apart are copied as one, the gap with them: a pooled
/// buffer's meshes lie at most one storage-offset alignment (256 bytes) apart.
const MERGE_GAP: u64 = 256;

/// The byte ranges a task's ingestions read, in the order they were asked for.
#[derive(Default)]
pub(super) struct RawCopy<'a> {
    requests: Vec<(&'a wgpu::Buffer, u64, u64)>,
}

/// One copy command: `(start, end)` of `buffer` lands at `at` in the raw buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Run {
    start: u64,
    end: u64,
    at: u64,
}

impl<'a> RawCopy<'a> {
    /// Asks for bytes `start..end` of `buffer` (both multiples of 4, within the buffer: the
    /// validation checked them); returns the request's index among the offsets [`Self::record`]
    /// returns.
    pub fn request(&mut self, buffer: &'a wgpu::Buffer, (start, end): (u64, u64)) -> usize {
        self.requests.push((buffer, start, end));
        self.requests.len() - 1
    }

    /// Copies every requested range into a new buffer, each merged range once, keeping every
    /// source buffer alive in `held` until the GPU task completes. Returns the buffer and, per
    /// request, the raw offset of its first byte.
    pub fn record(
        self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        held: &mut Vec<wgpu::Buffer>,
    ) -> (wgpu::Buffer, Vec<u64>) {
        let (runs, offsets) = self.plan();
        let size = runs
            .iter()
            .map(|(_, r)| r.end - r.start)
            .sum::<u64>()
            .max(4);
        let raw = crate::gpu::buffers::storage(device, "kickstart-rt raw geometry copy", size);
        let mut last: Option<&wgpu::Buffer> = None;
        for (buffer, run) in runs {
            encoder.copy_buffer_to_buffer(buffer, run.start, &raw, run.at, run.end - run.start);
            if last != Some(buffer) {
                held.push(buffer.clone());
                last = Some(buffer);
            }
        }
        (raw, offsets)
    }

    /// The copy commands (grouped by buffer, in order of their bytes) and each request's raw
    /// offset.
    fn plan(&self) -> (Vec<(&'a wgpu::Buffer, Run)>, Vec<u64>) {
        let mut order: Vec<usize> = (0..self.requests.len()).collect();
        order.sort_by(|&a, &b| {
            let (ba, sa, _) = self.requests[a];
            let (bb, sb, _) = self.requests[b];
            ba.cmp(bb).then(sa.cmp(&sb))
        });
        let mut runs: Vec<(&wgpu::Buffer, Run)> = Vec::new();
        let mut offsets = vec![0u64; self.requests.len()];
        let mut size = 0u64;
        for k in order {
            let (buffer, start, end) = self.requests[k];
            let joins = runs
                .last()
                .is_some_and(|(b, r)| *b == buffer && start <= r.end.saturating_add(MERGE_GAP));
            if joins {
                if let Some((_, r)) = runs.last_mut() {
                    if end > r.end {
                        size += end - r.end;
                        r.end = end;
                    }
                }
            } else {
                runs.push((
                    buffer,
                    Run {
                        start,
                        end,
                        at: size,
                    },
                ));
                size += end - start;
            }
            if let Some((_, r)) = runs.last() {
                offsets[k] = r.at + (start - r.start);
            }
        }
        (runs, offsets)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::testing;

    fn buffer(size: u64) -> wgpu::Buffer {
        testing::gpu()
            .device
            .create_buffer(&wgpu::BufferDescriptor {
                label: Some("raw copy test source"),
                size,
                usage: wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
    }

    /// Overlapping, touching and near ranges of one buffer become one copy; a range past the
    /// gap, or in another buffer, its own; every request's offset points at its own bytes
    /// within its run, and the raw buffer holds each source byte once.
    #[test]
    fn ranges_of_one_buffer_merge_and_each_request_finds_its_bytes() {
        let (a, b) = (buffer(1 << 16), buffer(1 << 16));
        let mut copy = RawCopy::default();
        let asked = [
            (&a, (1000, 2000)),
            (&b, (0, 400)),
            (&a, (0, 1000)),          // touches the first
            (&a, (1500, 1800)),       // inside the first
            (&a, (2000 + 256, 3000)), // within the gap
            (&a, (3000 + 260, 4000)), // past the gap: a run of its own
            (&b, (400, 800)),         // touches b's first
        ];
        let ids: Vec<usize> = asked.iter().map(|&(buf, r)| copy.request(buf, r)).collect();
        let (runs, offsets) = copy.plan();
        let shape: Vec<(bool, u64, u64)> = runs
            .iter()
            .map(|(buf, r)| (**buf == a, r.start, r.end))
            .collect();
        let mut want = vec![(true, 0, 3000), (true, 3260, 4000), (false, 0, 800)];
        if b < a {
            want.rotate_left(2);
        }
        assert_eq!(shape, want);
        // A request's offset: its run's raw position plus its distance from the run's start.
        for (&k, &(buf, (start, _))) in ids.iter().zip(&asked) {
            let (_, run) = runs
                .iter()
                .find(|(rb, r)| *rb == buf && r.start <= start && start < r.end)
                .unwrap_or_else(|| panic!("no run holds request {k}"));
            assert_eq!(offsets[k], run.at + (start - run.start), "request {k}");
        }
        // Runs are packed one after another.
        let mut at = 0;
        for (_, r) in &runs {
            assert_eq!(r.at, at);
            at += r.end - r.start;
        }
        assert_eq!(at, 3000 + 740 + 800);
    }
}
