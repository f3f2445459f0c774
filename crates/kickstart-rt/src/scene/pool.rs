//! Sub-allocation of one growable GPU buffer: the shared pools of DESIGN.md (one large buffer for
//! many geometries instead of a buffer per mesh). Ranges are in elements of a fixed size; freed
//! ranges return to the pool only once no in-flight GPU task can still read them.

use std::collections::BTreeMap;

/// A range of elements `[start, start + len)` handed out by a [`Pool`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Range {
    pub start: u32,
    pub len: u32,
}

/// A growable GPU buffer carved into ranges (first fit, coalescing frees).
pub(crate) struct Pool {
    label: &'static str,
    element_bytes: u64,
    usage: wgpu::BufferUsages,
    buffer: wgpu::Buffer,
    capacity: u32,
    /// Free ranges by start.
    free: BTreeMap<u32, u32>,
    /// Ranges freed by the application, with the serial of the last GPU task that used them.
    pending: Vec<(u64, Range)>,
    used: u64,
}

impl Pool {
    /// An empty pool whose elements are `element_bytes` each.
    pub fn new(device: &wgpu::Device, label: &'static str, element_bytes: u64) -> Self {
        let usage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST;
        let capacity = 16;
        Pool {
            label,
            element_bytes,
            usage,
            buffer: create(device, label, capacity as u64 * element_bytes, usage),
            capacity,
            free: BTreeMap::from([(0, capacity)]),
            pending: Vec::new(),
            used: 0,
        }
    }

    /// The buffer (changes when the pool grows: bind it after allocating).
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// Bytes handed out or waiting to be released.
    pub fn used_bytes(&self) -> u64 {
        (self.used + self.pending.iter().map(|(_, r)| r.len as u64).sum::<u64>())
            * self.element_bytes
    }

    /// Bytes of the buffer not handed out.
    pub fn reserve_bytes(&self) -> u64 {
        self.buffer.size() - self.used_bytes().min(self.buffer.size())
    }

    /// `len` elements (at least 1), growing the buffer (copying its contents inside `encoder`)
    /// when no free range fits. Fails only when the pool would exceed `max_bytes`.
    pub fn alloc(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        len: u32,
        max_bytes: u64,
    ) -> Option<Range> {
        let len = len.max(1);
        if let Some(r) = self.take_free(len) {
            return Some(r);
        }
        // Grow: double, or more when one allocation needs it; the tail becomes free.
        let needed = self.capacity as u64 + len as u64;
        let mut new_cap = (self.capacity as u64 * 2).max(needed);
        let max_elems = max_bytes / self.element_bytes;
        if needed > max_elems || needed > u32::MAX as u64 {
            return None;
        }
        new_cap = new_cap.min(max_elems).min(u32::MAX as u64);
        let new = create(device, self.label, new_cap * self.element_bytes, self.usage);
        encoder.copy_buffer_to_buffer(&self.buffer, 0, &new, 0, self.buffer.size());
        // The old buffer stays alive while recorded commands use it (wgpu reference counts it).
        self.buffer = new;
        let old_cap = self.capacity;
        self.capacity = new_cap as u32;
        self.release(Range {
            start: old_cap,
            len: self.capacity - old_cap,
        });
        self.take_free(len)
    }

    fn take_free(&mut self, len: u32) -> Option<Range> {
        let (&start, &flen) = self.free.iter().find(|(_, &l)| l >= len)?;
        self.free.remove(&start);
        if flen > len {
            self.free.insert(start + len, flen - len);
        }
        self.used += len as u64;
        Some(Range { start, len })
    }

    /// Returns `r` once every GPU task up to serial `last_used` has completed (see
    /// [`Pool::collect`]).
    pub fn free_after(&mut self, r: Range, last_used: u64) {
        self.used -= r.len as u64;
        self.pending.push((last_used, r));
    }

    /// Releases pending ranges whose last user is older than `oldest_in_flight`.
    pub fn collect(&mut self, oldest_in_flight: u64) {
        let mut ready = Vec::new();
        self.pending.retain(|&(last, r)| {
            let done = last < oldest_in_flight;
            if done {
                ready.push(r);
            }
            !done
        });
        for r in ready {
            self.release(r);
        }
    }

    /// Puts `r` on the free list, merged with its neighbours (`used` is the caller's business).
    fn release(&mut self, r: Range) {
        let mut start = r.start;
        let mut len = r.len;
        if let Some((&ps, &pl)) = self.free.range(..start).next_back() {
            if ps + pl == start {
                self.free.remove(&ps);
                start = ps;
                len += pl;
            }
        }
        if let Some(&nl) = self.free.get(&(r.start + r.len)) {
            self.free.remove(&(r.start + r.len));
            len += nl;
        }
        self.free.insert(start, len);
    }
}

fn create(
    device: &wgpu::Device,
    label: &str,
    size: u64,
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(256),
        usage,
        mapped_at_creation: false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::testing::gpu;

    #[test]
    fn allocations_do_not_overlap_grow_and_coalesce() {
        let g = gpu();
        let mut enc = g.device.create_command_encoder(&Default::default());
        let mut p = Pool::new(&g.device, "test pool", 16);
        let a = p.alloc(&g.device, &mut enc, 10, u64::MAX).unwrap();
        let b = p.alloc(&g.device, &mut enc, 100, u64::MAX).unwrap();
        let c = p.alloc(&g.device, &mut enc, 5, u64::MAX).unwrap();
        let mut rs = [a, b, c];
        rs.sort_by_key(|r| r.start);
        for w in rs.windows(2) {
            assert!(w[0].start + w[0].len <= w[1].start, "{rs:?}");
        }
        assert!(p.buffer().size() >= 115 * 16);
        assert_eq!(p.used_bytes(), 115 * 16);
        p.free_after(b, 7);
        assert_eq!(p.used_bytes(), 115 * 16, "pending frees still count");
        p.collect(7);
        assert_eq!(p.used_bytes(), 115 * 16, "task 7 may still be in flight");
        p.collect(8);
        assert_eq!(p.used_bytes(), 15 * 16);
        // The freed hole is reused without growing.
        let size = p.buffer().size();
        let d = p.alloc(&g.device, &mut enc, 100, u64::MAX).unwrap();
        assert_eq!(p.buffer().size(), size);
        assert!(d.start + d.len <= size as u32 / 16);
        assert!(p.alloc(&g.device, &mut enc, 1 << 20, 1024).is_none());
        g.queue.submit([enc.finish()]);
    }
}
