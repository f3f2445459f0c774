//! Sub-allocation of one growable GPU buffer: the shared pools of DESIGN.md (one large buffer for
//! many geometries instead of a buffer per mesh). Ranges are in elements of a fixed size; freed
//! ranges return to the pool only once no in-flight GPU task can still read them.
//!
//! The bookkeeping ([`Ledger`]) is separate from the buffer so that `build_gpu_task`'s plan can
//! run a task's allocations on a copy first: a task whose allocations would exceed the device's
//! limit is refused before anything changes, and the record phase, repeating the same
//! allocations on the real pool, cannot fail.

use std::collections::BTreeMap;

/// A range of elements `[start, start + len)` handed out by a [`Pool`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Range {
    pub start: u32,
    pub len: u32,
}

/// How [`Ledger::pack`] moved one run of elements in use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Move {
    /// First element before.
    pub from: u32,
    /// First element after.
    pub to: u32,
    /// Elements.
    pub len: u32,
}

impl Move {
    /// Where a range that started at `start` starts after the moves (`None`: it was not in
    /// use, so it did not move).
    pub fn moved(moves: &[Move], start: u32) -> Option<u32> {
        let i = moves.partition_point(|m| m.from <= start).checked_sub(1)?;
        let m = moves[i];
        (start - m.from < m.len).then(|| m.to + (start - m.from))
    }
}

/// The CPU side of a [`Pool`]: its capacity and which ranges are free, handed out or waiting to
/// be released. Cloning it and allocating on the copy predicts exactly what the pool will hand
/// out (and whether it grows) for the same calls in the same order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Ledger {
    element_bytes: u64,
    capacity: u32,
    /// Free ranges by start.
    free: BTreeMap<u32, u32>,
    /// Ranges freed by the application, with the serial of the last GPU task that used them.
    pending: Vec<(u64, Range)>,
    used: u64,
}

/// Elements of an empty pool (and the least a trimmed one keeps).
const MIN_CAPACITY: u32 = 16;

impl Ledger {
    /// An empty ledger of `capacity` elements of `element_bytes` each.
    fn new(element_bytes: u64, capacity: u32) -> Self {
        Ledger {
            element_bytes,
            capacity,
            free: BTreeMap::from([(0, capacity)]),
            pending: Vec::new(),
            used: 0,
        }
    }

    /// Elements the buffer holds.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// Bytes handed out or waiting to be released.
    pub fn used_bytes(&self) -> u64 {
        (self.used + self.pending.iter().map(|(_, r)| r.len as u64).sum::<u64>())
            * self.element_bytes
    }

    /// `len` elements (at least 1), first fit; when nothing fits, the capacity grows (doubles,
    /// or more when one allocation needs it) and the new tail is free. `None` only when the
    /// capacity would exceed `max_bytes`; then nothing changed.
    pub fn alloc(&mut self, len: u32, max_bytes: u64) -> Option<Range> {
        let len = len.max(1);
        if let Some(r) = self.take_free(len) {
            return Some(r);
        }
        let needed = self.capacity as u64 + len as u64;
        let max_elems = max_bytes / self.element_bytes;
        if needed > max_elems || needed > u32::MAX as u64 {
            return None;
        }
        let new_cap = (self.capacity as u64 * 2)
            .max(needed)
            .min(max_elems)
            .min(u32::MAX as u64);
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
    /// [`Ledger::collect`]).
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

    /// Whether ranges wait for in-flight tasks before they are free.
    pub fn has_pending(&self) -> bool {
        !self.pending.is_empty()
    }

    /// Elements free at the end of the buffer.
    fn free_tail(&self) -> u32 {
        match self.free.iter().next_back() {
            Some((&start, &len)) if start + len == self.capacity => len,
            _ => 0,
        }
    }

    /// Makes room for `total` more elements at the end before a task's allocations of that
    /// many, so that they grow the buffer once instead of doubling it on the way (a scene
    /// loaded in one task ends up with an eighth of headroom, not up to half). Growth is at
    /// least an eighth of the capacity, so that streaming small allocations stays amortised.
    /// Nothing changes when the capacity would pass `max_bytes` (the allocations then are
    /// refused as usual). Returns whether it grew.
    pub fn reserve(&mut self, total: u64, max_bytes: u64) -> bool {
        let tail = u64::from(self.free_tail());
        if total <= tail {
            return false;
        }
        let cap = u64::from(self.capacity);
        let new_cap = (cap + total - tail).max(cap + cap / 8);
        if new_cap * self.element_bytes > max_bytes || new_cap > u64::from(u32::MAX) {
            return false;
        }
        let old_cap = self.capacity;
        self.capacity = new_cap as u32;
        self.release(Range {
            start: old_cap,
            len: self.capacity - old_cap,
        });
        true
    }

    /// Gives back the free tail when it is worth a copy: at least a quarter of the capacity, or
    /// anything when no range is in use or pending (then nothing needs copying). The capacity
    /// shrinks to the end of the last range handed out or pending (at least [`MIN_CAPACITY`]
    /// elements). Returns whether it shrank.
    pub fn trim_free_tail(&mut self) -> bool {
        let Some((&start, &len)) = self.free.iter().next_back() else {
            return false;
        };
        let new_cap = start.max(MIN_CAPACITY);
        let idle = self.used_bytes() == 0;
        if start + len != self.capacity
            || new_cap >= self.capacity
            || (!idle && len < self.capacity / 4)
        {
            return false;
        }
        self.free.remove(&start);
        if new_cap > start {
            self.free.insert(start, new_cap - start);
        }
        self.capacity = new_cap;
        true
    }

    /// Packs the ranges in use to the front, in order, when anything is not in use (free, or
    /// waiting for in-flight tasks): a copy of what is in use, once per quiet spell after
    /// builds, against the holes between ranges that a tail trim cannot give back (a compaction
    /// leaves one after every fast-trace BLAS); the capacity becomes what is
    /// in use (at least [`MIN_CAPACITY`]). Ranges waiting for in-flight tasks are dropped: those
    /// tasks read the old buffer, which the new one replaces. Returns the moves of the runs in
    /// use, in order, or `None` when nothing changed.
    pub fn pack(&mut self) -> Option<Vec<Move>> {
        if self.used >= u64::from(self.capacity) || self.capacity <= MIN_CAPACITY {
            return None;
        }
        let mut gaps: Vec<(u32, u32)> = self.free.iter().map(|(&s, &l)| (s, l)).collect();
        gaps.extend(self.pending.iter().map(|(_, r)| (r.start, r.len)));
        gaps.sort_unstable();
        let mut moves = Vec::new();
        let (mut at, mut to) = (0u32, 0u32);
        let mut run = |from: u32, end: u32, moves: &mut Vec<Move>| {
            if end > from {
                moves.push(Move {
                    from,
                    to,
                    len: end - from,
                });
                to += end - from;
            }
        };
        for (start, len) in gaps {
            run(at, start, &mut moves);
            at = start + len;
        }
        run(at, self.capacity, &mut moves);
        let packed = u32::try_from(self.used).unwrap_or(u32::MAX);
        let capacity = packed.max(MIN_CAPACITY);
        self.capacity = capacity;
        self.free.clear();
        if capacity > packed {
            self.free.insert(packed, capacity - packed);
        }
        self.pending.clear();
        Some(moves)
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

/// A growable GPU buffer carved into ranges (first fit, coalescing frees) by its [`Ledger`].
pub(crate) struct Pool {
    label: &'static str,
    usage: wgpu::BufferUsages,
    buffer: wgpu::Buffer,
    ledger: Ledger,
}

impl Pool {
    /// An empty pool whose elements are `element_bytes` each.
    pub fn new(device: &wgpu::Device, label: &'static str, element_bytes: u64) -> Self {
        Self::with_usage(device, label, element_bytes, wgpu::BufferUsages::empty())
    }

    /// An empty pool whose buffer also has `extra` usage (e.g. `BLAS_INPUT`, for the driver's
    /// acceleration structures to read).
    pub fn with_usage(
        device: &wgpu::Device,
        label: &'static str,
        element_bytes: u64,
        extra: wgpu::BufferUsages,
    ) -> Self {
        let usage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST
            | extra;
        let ledger = Ledger::new(element_bytes, MIN_CAPACITY);
        Pool {
            label,
            usage,
            buffer: create(device, label, ledger.capacity as u64 * element_bytes, usage),
            ledger,
        }
    }

    /// The buffer (changes when the pool grows: bind it after allocating).
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// The bookkeeping, to simulate allocations on a copy of it.
    pub fn ledger(&self) -> &Ledger {
        &self.ledger
    }

    /// Bytes handed out or waiting to be released.
    pub fn used_bytes(&self) -> u64 {
        self.ledger.used_bytes()
    }

    /// Bytes of the buffer not handed out.
    pub fn reserve_bytes(&self) -> u64 {
        self.buffer.size() - self.used_bytes().min(self.buffer.size())
    }

    /// `len` elements (at least 1), growing the buffer (copying its contents inside `encoder`)
    /// when no free range fits. Fails only when the pool would exceed `max_bytes`, exactly when
    /// [`Ledger::alloc`] on a copy of [`Pool::ledger`] does.
    pub fn alloc(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        len: u32,
        max_bytes: u64,
    ) -> Option<Range> {
        let old_cap = self.ledger.capacity();
        let r = self.ledger.alloc(len, max_bytes)?;
        if self.ledger.capacity() != old_cap {
            self.regrow(device, encoder);
        }
        Some(r)
    }

    /// Returns `r` once every GPU task up to serial `last_used` has completed (see
    /// [`Pool::collect`]).
    pub fn free_after(&mut self, r: Range, last_used: u64) {
        self.ledger.free_after(r, last_used);
    }

    /// Releases pending ranges whose last user is older than `oldest_in_flight`.
    pub fn collect(&mut self, oldest_in_flight: u64) {
        self.ledger.collect(oldest_in_flight);
    }

    /// Gives the free tail back ([`Ledger::trim_free_tail`]): a smaller buffer holding the
    /// ranges in use, copied inside `encoder` (nothing to copy when none is). Returns whether it
    /// shrank.
    pub fn trim(&mut self, device: &wgpu::Device, encoder: &mut wgpu::CommandEncoder) -> bool {
        let idle = self.ledger.used_bytes() == 0;
        if !self.ledger.trim_free_tail() {
            return false;
        }
        let bytes = self.ledger.capacity() as u64 * self.ledger.element_bytes;
        let new = create(device, self.label, bytes, self.usage);
        if !idle {
            let kept = new.size().min(self.buffer.size());
            encoder.copy_buffer_to_buffer(&self.buffer, 0, &new, 0, kept);
        }
        // As when growing: wgpu keeps the old buffer alive while recorded commands use it.
        self.buffer = new;
        true
    }

    /// [`Ledger::pack`] on the pool: a buffer of the packed capacity, the runs in use copied
    /// into it inside `encoder`. Returns the moves, or `None` when nothing changed.
    pub fn pack(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Option<Vec<Move>> {
        let moves = self.ledger.pack()?;
        let bytes = u64::from(self.ledger.capacity()) * self.ledger.element_bytes;
        let new = create(device, self.label, bytes, self.usage);
        let e = self.ledger.element_bytes;
        for m in &moves {
            encoder.copy_buffer_to_buffer(
                &self.buffer,
                u64::from(m.from) * e,
                &new,
                u64::from(m.to) * e,
                u64::from(m.len) * e,
            );
        }
        // As when growing: wgpu keeps the old buffer alive while recorded commands use it.
        self.buffer = new;
        Some(moves)
    }

    /// [`Ledger::reserve`] on the pool: grows the buffer (copying its contents inside
    /// `encoder`) so that `total` more elements fit at its end.
    pub fn reserve(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        total: u64,
        max_bytes: u64,
    ) {
        if self.ledger.reserve(total, max_bytes) {
            self.regrow(device, encoder);
        }
    }

    /// A buffer of the ledger's (larger) capacity, holding the old one's contents.
    fn regrow(&mut self, device: &wgpu::Device, encoder: &mut wgpu::CommandEncoder) {
        let bytes = self.ledger.capacity() as u64 * self.ledger.element_bytes;
        let new = create(device, self.label, bytes, self.usage);
        encoder.copy_buffer_to_buffer(&self.buffer, 0, &new, 0, self.buffer.size());
        // The old buffer stays alive while recorded commands use it (wgpu reference counts it).
        self.buffer = new;
    }
}

/// A pool buffer of `size` bytes (at least 256).
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

    /// A pool gives its free tail back, keeping the contents of the ranges still in use, and
    /// never a range in use or waiting for its tasks.
    #[test]
    fn trimming_gives_the_free_tail_back_and_keeps_the_contents() {
        let g = gpu();
        let mut enc = g.device.create_command_encoder(&Default::default());
        let mut p = Pool::new(&g.device, "test pool", 16);
        let a = p.alloc(&g.device, &mut enc, 10, u64::MAX).unwrap();
        let b = p.alloc(&g.device, &mut enc, 90, u64::MAX).unwrap();
        let c = p.alloc(&g.device, &mut enc, 200, u64::MAX).unwrap();
        // Growth left a few elements free past `c`: not worth a copy.
        assert!(!p.trim(&g.device, &mut enc), "a small tail stays");
        assert_eq!(p.ledger().capacity(), c.start + c.len + 6);
        // Known contents in `a`, then `c` freed: pending until task 3 completes.
        let words: Vec<u32> = (0..a.len * 4).map(|i| 0xC0DE_0000 + i).collect();
        let src = crate::gpu::testing::buffer_with(bytemuck::cast_slice(&words));
        enc.copy_buffer_to_buffer(&src, 0, p.buffer(), a.start as u64 * 16, a.len as u64 * 16);
        p.free_after(c, 3);
        assert!(
            !p.trim(&g.device, &mut enc),
            "the pending range is not given back"
        );
        p.collect(4);
        assert!(p.trim(&g.device, &mut enc), "two thirds free");
        assert_eq!(p.ledger().capacity(), b.start + b.len);
        assert_eq!(p.buffer().size(), u64::from(b.start + b.len) * 16);
        p.free_after(b, 4);
        p.collect(5);
        assert!(p.trim(&g.device, &mut enc));
        assert_eq!(
            p.ledger().capacity(),
            MIN_CAPACITY,
            "the least a pool keeps"
        );
        assert_eq!(p.used_bytes(), u64::from(a.len) * 16);
        g.queue.submit([enc.finish()]);
        let bytes = crate::gpu::testing::read_back(p.buffer(), 0, u64::from(a.len) * 16);
        assert_eq!(bytemuck::cast_slice::<u8, u32>(&bytes), &words[..]);
        // Still a working pool: it grows again from the trimmed size.
        let mut enc = g.device.create_command_encoder(&Default::default());
        let d = p.alloc(&g.device, &mut enc, 40, u64::MAX).unwrap();
        assert_eq!(d.start, a.len);
        g.queue.submit([enc.finish()]);
    }

    /// Packing moves the ranges in use to the front in order, closing the holes between them
    /// (a range waiting for in-flight tasks is a hole too: those tasks read the old buffer), and
    /// keeps their contents; `Move::moved` finds where a range went.
    #[test]
    fn packing_closes_the_holes_and_keeps_the_contents() {
        let g = gpu();
        let mut enc = g.device.create_command_encoder(&Default::default());
        let mut p = Pool::new(&g.device, "test pool", 16);
        let r: Vec<Range> = [10, 20, 30, 40, 50]
            .iter()
            .map(|&n| p.alloc(&g.device, &mut enc, n, u64::MAX).unwrap())
            .collect();
        // Known contents in ranges 1 and 3.
        let words: Vec<u32> = (0..(r[1].len + r[3].len) * 4)
            .map(|i| 0xC0DE_0000 + i)
            .collect();
        let src = crate::gpu::testing::buffer_with(bytemuck::cast_slice(&words));
        let split = u64::from(r[1].len) * 16;
        enc.copy_buffer_to_buffer(&src, 0, p.buffer(), u64::from(r[1].start) * 16, split);
        enc.copy_buffer_to_buffer(
            &src,
            split,
            p.buffer(),
            u64::from(r[3].start) * 16,
            u64::from(r[3].len) * 16,
        );
        // Range 0 free, range 2 waiting for task 7, and the tail of range 4 given back.
        p.free_after(r[0], 1);
        p.collect(2);
        p.free_after(r[2], 7);
        p.free_after(
            Range {
                start: r[4].start + 5,
                len: 45,
            },
            1,
        );
        p.collect(2);
        let moves = p.pack(&g.device, &mut enc).expect("holes to close");
        let m = |from, to, len| Move { from, to, len };
        assert_eq!(
            moves,
            [m(10, 0, 20), m(60, 20, 45)],
            "ranges 1, and 3 with 4's head"
        );
        assert_eq!(Move::moved(&moves, r[1].start), Some(0));
        assert_eq!(Move::moved(&moves, r[3].start), Some(20));
        assert_eq!(Move::moved(&moves, r[4].start), Some(60));
        assert_eq!(Move::moved(&moves, r[0].start), None);
        assert_eq!(Move::moved(&moves, r[2].start), None);
        assert_eq!(p.ledger().capacity(), 65);
        assert_eq!(
            p.used_bytes(),
            65 * 16,
            "the waiting range is gone with the old buffer"
        );
        assert!(!p.ledger().has_pending());
        assert_eq!(p.pack(&g.device, &mut enc), None, "nothing left to close");
        g.queue.submit([enc.finish()]);
        let bytes =
            crate::gpu::testing::read_back(p.buffer(), 0, u64::from(r[1].len + r[3].len) * 16);
        assert_eq!(bytemuck::cast_slice::<u8, u32>(&bytes), &words[..]);
        // Still a working pool: the next range goes at the end.
        let mut enc = g.device.create_command_encoder(&Default::default());
        assert_eq!(p.alloc(&g.device, &mut enc, 8, u64::MAX).unwrap().start, 65);
        g.queue.submit([enc.finish()]);
    }

    /// Reserving room for a task's allocations grows the pool once, to what they need (or by
    /// an eighth of the capacity at least), and the allocations then fit without growing.
    #[test]
    fn reserving_grows_once_to_what_a_task_needs() {
        let g = gpu();
        let mut enc = g.device.create_command_encoder(&Default::default());
        let mut p = Pool::new(&g.device, "test pool", 16);
        let sizes = [1000, 30, 2000, 7, 500];
        let total: u64 = sizes.iter().map(|&n| u64::from(n)).sum();
        p.reserve(&g.device, &mut enc, total, u64::MAX);
        assert_eq!(
            u64::from(p.ledger().capacity()),
            total,
            "exactly what the task needs"
        );
        let cap = p.ledger().capacity();
        for n in sizes {
            p.alloc(&g.device, &mut enc, n, u64::MAX).unwrap();
        }
        assert_eq!(
            p.ledger().capacity(),
            cap,
            "no growth after the reservation"
        );
        // A small reservation grows by an eighth of the capacity.
        p.reserve(&g.device, &mut enc, 40, u64::MAX);
        assert_eq!(p.ledger().capacity(), cap + cap / 8);
        assert_eq!(p.buffer().size(), u64::from(cap + cap / 8) * 16);
        // Past the limit: nothing changes.
        assert!(!p.ledger().clone().reserve(1 << 30, 1 << 20));
        g.queue.submit([enc.finish()]);
    }

    /// One call on a pool, as the plan and the record phase make them.
    #[derive(Clone, Copy)]
    enum Op {
        Alloc(u32, u64),
        /// Frees the `n`th range handed out so far, last used by task `serial`.
        Free(usize, u64),
        Collect(u64),
        /// Room for this many elements more, under a limit of this many bytes.
        Reserve(u64, u64),
    }

    /// The plan simulates a task's allocations on a copy of the ledger; the record phase then
    /// makes them on the pool. The copy must predict every range, every refusal, the growth and
    /// the used bytes exactly, also after frees wait for in-flight tasks and are collected (else
    /// the record phase could fail after the plan accepted the task).
    #[test]
    fn a_copy_of_the_ledger_predicts_the_pool_exactly() {
        use Op::*;
        let g = gpu();
        let mut enc = g.device.create_command_encoder(&Default::default());
        let mut pool = Pool::new(&g.device, "test pool", 16);
        let ops = [
            Alloc(10, u64::MAX),
            Alloc(100, u64::MAX), // grows past doubling
            Alloc(5, u64::MAX),
            Free(1, 7),
            Alloc(50, u64::MAX), // the pending range is not reused yet: grows
            Collect(7),          // task 7 may still be in flight
            Alloc(60, u64::MAX),
            Collect(8),
            Alloc(90, u64::MAX), // reuses the collected hole
            Free(0, 9),
            Free(2, 9),
            Collect(10),
            Alloc(15, u64::MAX),
            Alloc(1 << 20, 1 << 16), // past the limit: refused, nothing changes
            Alloc(0, u64::MAX),      // at least one element
            Alloc(100, 400 * 16),    // doubling would pass the limit: grows to it
            Reserve(300, u64::MAX),  // one growth for the next three
            Alloc(120, u64::MAX),
            Alloc(90, u64::MAX),
            Alloc(90, u64::MAX),
            Reserve(1 << 20, 1 << 16), // past the limit: nothing changes
        ];
        let mut predicted = pool.ledger().clone();
        let (mut real, mut sim) = (Vec::new(), Vec::new());
        for (i, op) in ops.into_iter().enumerate() {
            match op {
                Alloc(len, max) => {
                    let size = pool.buffer().size();
                    let r = pool.alloc(&g.device, &mut enc, len, max);
                    let s = predicted.alloc(len, max);
                    assert_eq!(r, s, "op {i}: the range");
                    if r.is_none() {
                        assert_eq!(
                            pool.buffer().size(),
                            size,
                            "op {i}: a refusal grows nothing"
                        );
                    }
                    real.push(r);
                    sim.push(s);
                }
                Free(n, serial) => {
                    pool.free_after(real[n].unwrap(), serial);
                    predicted.free_after(sim[n].unwrap(), serial);
                }
                Collect(oldest) => {
                    pool.collect(oldest);
                    predicted.collect(oldest);
                }
                Reserve(total, max) => {
                    pool.reserve(&g.device, &mut enc, total, max);
                    predicted.reserve(total, max);
                }
            }
            assert_eq!(pool.ledger(), &predicted, "op {i}: the bookkeeping");
            assert_eq!(
                pool.buffer().size(),
                (predicted.capacity() as u64 * 16).max(256),
                "op {i}: the buffer follows the predicted capacity"
            );
            assert_eq!(pool.used_bytes(), predicted.used_bytes(), "op {i}");
        }
        // The refusal and the growth limited to the limit happened (the sequence covers them).
        let at = |start, len| Some(Range { start, len });
        assert_eq!(real[1], at(10, 100));
        assert_eq!(real[3], at(115, 50));
        assert_eq!(real[5], at(10, 90));
        assert_eq!(real[6], at(100, 15));
        assert_eq!(real[7], None);
        // Grown to the limit (400), then once by the reservation: the three allocations' 300
        // elements less the 75 free at the end; they fit without growing again.
        assert_eq!(predicted.capacity(), 400 + 300 - 75);
        g.queue.submit([enc.finish()]);
    }
}
