//! The denoisers' guides (a surface record per grid pixel: clip-space depth, normal, roughness;
//! see `shaders/denoise/common.wgsl`), this frame's and the previous frame's, shared by the
//! denoising contexts whose frames write identical guides.
//!
//! A context's temporal pass writes this frame's guide from its G-buffer inputs; the next frame
//! reads it as the previous guide. Contexts denoised in the same GPU task from the same G-buffer
//! textures, camera, viewport and traced-pixel pattern (a [`GuideKey`]) write the same guide, so
//! they share one pair of guide buffers instead of a pair each (an engine denoising reflections,
//! GI, AO and shadows of one view keeps one pair, not four). A context whose inputs part from
//! its partners' gets a pair of its own, with the previous guide copied, so its history carries
//! on. Sharing is limited to one GPU task: only within one task do equal inputs mean the same
//! frame.
//!
//! Textures are compared by identity ([`wgpu::Texture`]'s): views of other subresources of one
//! texture with the same camera and viewport would be taken for the same input.

use crate::trace::gbuffer::GBufferParams;

/// Bytes per pixel of a guide (`vec2<u32>`: the depth, the normal and roughness).
pub(crate) const GUIDE_BYTES: u64 = 8;

/// Everything a frame's guide is made of besides the textures' contents: two frames of one GPU
/// task with equal keys write the same guide.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub(crate) struct GuideKey {
    /// The G-buffer uniform (camera, jitter, viewport, decoding of each input), as bytes.
    gbuffer: Vec<u8>,
    /// Depth, normal and roughness textures.
    textures: [Option<wgpu::Texture>; 3],
    /// The grid: size, block size, traced pixel, checkerboard mode.
    grid: [u32; 6],
}

impl GuideKey {
    /// The key of a frame with G-buffer uniform `gbuffer`, textures `textures` (depth, normal,
    /// roughness) and grid `grid` (width, height, block size, traced x, traced y, checkerboard).
    pub fn new(
        gbuffer: &GBufferParams,
        textures: [Option<&wgpu::Texture>; 3],
        grid: [u32; 6],
    ) -> Self {
        GuideKey {
            gbuffer: bytemuck::bytes_of(gbuffer).to_vec(),
            textures: textures.map(|t| t.cloned()),
            grid,
        }
    }
}

/// One pair of guide buffers.
struct GuidePair {
    buffers: [wgpu::Buffer; 2],
    /// Grid pixels each buffer holds.
    pixels: u64,
    /// Index of this frame's guide (the last one written); the other is the previous frame's.
    cur: usize,
    /// The task and key of the last write, and of the one before (what the previous guide
    /// holds).
    last_write: Option<(u64, GuideKey)>,
    prev_write: Option<(u64, GuideKey)>,
    /// Serial of the last GPU task that used it.
    last_used: u64,
}

impl GuidePair {
    fn new(device: &wgpu::Device, pixels: u64) -> Self {
        let buffer = || {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("kickstart-rt denoiser guide"),
                size: pixels.max(1) * GUIDE_BYTES,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        GuidePair {
            buffers: [buffer(), buffer()],
            pixels,
            cur: 0,
            last_write: None,
            prev_write: None,
            last_used: 0,
        }
    }

    fn written_in(&self, serial: u64) -> Option<&GuideKey> {
        self.last_write
            .as_ref()
            .filter(|(s, _)| *s == serial)
            .map(|(_, k)| k)
    }

    /// Makes the other buffer this frame's guide, written by task `serial` with `key`.
    fn advance(&mut self, serial: u64, key: GuideKey) {
        self.cur = 1 - self.cur;
        self.prev_write = self.last_write.take();
        self.last_write = Some((serial, key));
    }
}

/// The guides a frame binds: the previous frame's (read) and this frame's (written).
pub(crate) struct GuideBinding {
    pub prev: wgpu::Buffer,
    pub cur: wgpu::Buffer,
}

/// What a context's frame asks of the guides.
pub(crate) struct GuideRequest {
    pub key: GuideKey,
    /// Grid pixels.
    pub pixels: u64,
    /// The frame starts its history over: the previous guide is not read.
    pub discard: bool,
    pub serial: u64,
}

/// Every guide pair, by id; contexts hold the id of theirs.
#[derive(Default)]
pub(crate) struct Guides {
    pairs: Vec<Option<GuidePair>>,
}

impl Guides {
    /// The guides of a context's frame; `own` is the context's pair (updated when it joins,
    /// leaves or gets one). `encoder` receives the copy of the previous guide when the context
    /// leaves a shared pair.
    pub fn for_frame(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        own: &mut Option<usize>,
        req: GuideRequest,
    ) -> GuideBinding {
        let serial = req.serial;
        if let Some(q) = self.written_with(serial, &req.key, req.pixels) {
            // Joining keeps the context's previous guide only where it is the same content.
            let joins = match *own {
                Some(o) => o == q || req.discard || self.same_previous(o, q),
                None => true,
            };
            if let Some(p) = self.pairs[q].as_mut().filter(|_| joins) {
                *own = Some(q);
                return binding(p, serial);
            }
        }
        let own_pair = own.and_then(|o| self.pair(o).map(|p| (o, p)));
        let fresh = match own_pair {
            // Its own pair, not yet written by this task: this frame's guide goes to the other
            // buffer.
            Some((o, p)) if p.written_in(serial).is_none() && p.pixels == req.pixels => {
                if let Some(p) = self.pairs[o].as_mut() {
                    p.advance(serial, req.key);
                    return binding(p, serial);
                }
                GuidePair::new(device, req.pixels)
            }
            // A partner wrote the pair with other inputs: a pair of its own, holding a copy of
            // the previous guide when the history carries on.
            Some((_, p)) if !req.discard && p.pixels == req.pixels => {
                let fresh = GuidePair::new(device, req.pixels);
                let bytes = p.pixels * GUIDE_BYTES;
                let prev = &p.buffers[1 - p.cur];
                encoder.copy_buffer_to_buffer(prev, 0, &fresh.buffers[0], 0, bytes);
                GuidePair {
                    cur: 1,
                    prev_write: p.prev_write.clone(),
                    last_write: Some((serial, req.key)),
                    ..fresh
                }
            }
            _ => GuidePair {
                last_write: Some((serial, req.key)),
                ..GuidePair::new(device, req.pixels)
            },
        };
        let mut fresh = fresh;
        let bound = binding(&mut fresh, serial);
        *own = Some(self.insert(fresh));
        bound
    }

    fn pair(&self, id: usize) -> Option<&GuidePair> {
        self.pairs.get(id).and_then(Option::as_ref)
    }

    /// A pair written by task `serial` with `key`, of `pixels` pixels.
    fn written_with(&self, serial: u64, key: &GuideKey, pixels: u64) -> Option<usize> {
        self.pairs.iter().position(|p| {
            p.as_ref()
                .is_some_and(|p| p.pixels == pixels && p.written_in(serial) == Some(key))
        })
    }

    /// Whether pair `o`'s last guide (a context's previous guide) is what pair `q` held before
    /// this task wrote it: both written by the same task with the same key.
    fn same_previous(&self, o: usize, q: usize) -> bool {
        match (self.pair(o), self.pair(q)) {
            (Some(o), Some(q)) => o.last_write.is_some() && o.last_write == q.prev_write,
            _ => false,
        }
    }

    fn insert(&mut self, pair: GuidePair) -> usize {
        match self.pairs.iter().position(Option::is_none) {
            Some(free) => {
                self.pairs[free] = Some(pair);
                free
            }
            None => {
                self.pairs.push(Some(pair));
                self.pairs.len() - 1
            }
        }
    }

    /// Releases the pairs no live context holds (`held`) once no task from `oldest_in_flight`
    /// on uses them.
    pub fn collect(&mut self, oldest_in_flight: u64, held: &[usize]) {
        for (id, slot) in self.pairs.iter_mut().enumerate() {
            if slot
                .as_ref()
                .is_some_and(|p| !held.contains(&id) && p.last_used < oldest_in_flight)
            {
                *slot = None;
            }
        }
    }

    /// GPU bytes held.
    pub fn bytes(&self) -> u64 {
        self.pairs
            .iter()
            .flatten()
            .map(|p| 2 * p.pixels.max(1) * GUIDE_BYTES)
            .sum()
    }
}

/// The buffers of `p` for task `serial` (which it marks as its last user).
fn binding(p: &mut GuidePair, serial: u64) -> GuideBinding {
    p.last_used = serial;
    GuideBinding {
        prev: p.buffers[1 - p.cur].clone(),
        cur: p.buffers[p.cur].clone(),
    }
}
