//! The hardware backend's acceleration structures: one driver BLAS per geometry, built from the
//! geometry's triangles in the SDK's own triangle pool (so every vertex format, component
//! transform and index range the ingestion handles keeps working, and a hit's primitive index
//! within the BLAS names a pool slot), and one driver TLAS over the instance table.
//!
//! The software scene is still built alongside: the lighting cache allocates its tiles from the
//! sorted triangle pool, which the software build writes, and the driver's structures are built
//! from that pool. The TLAS is made from the same instance records the software traversal reads
//! (mirrored here when they are uploaded), so both backends see the same instances.

use std::collections::HashMap;

use crate::gpu::Recorder;

/// The start of the labels of one context's driver acceleration structures: the SDK's memory
/// count finds them in wgpu's allocator report by it. The report is the device's, so the label
/// names the context: another context on the same device (or a test beside it) must not be
/// counted as this one's. The trailing space keeps context 1 from matching context 12.
pub(crate) fn driver_label_prefix(context_id: u32) -> String {
    format!("kickstart-rt driver (context {context_id}) ")
}

/// Words of one instance record (128 bytes, the instance table's record; the context writes
/// them: `instance_record`). Words 0–11: the object-to-world rows; 12–23: the world-to-object
/// rows; 24: the geometry slot; 25: the inclusion mask; 26: bit 0, in the TLAS.
const RECORD_WORDS: usize = 32;
/// Vertices of the pool are `vec4<f32>` (xyz and the primitive index's bits in w).
const VERTEX_STRIDE: u64 = 16;

/// One geometry's driver BLAS.
struct GeometryBlas {
    blas: wgpu::Blas,
    /// Its size, as created (an update must keep it).
    size: wgpu::BlasTriangleGeometrySizeDescriptor,
    /// First triangle in the pool.
    first_triangle: u32,
    /// Created for in-place updates (`allow_update` geometry).
    updatable: bool,
}

/// A BLAS build or update recorded by the next [`HardwareScene::record`].
struct PendingBlas {
    geometry: u32,
    /// An in-place update of a built BLAS (a refit), not a new build.
    update: bool,
}

/// The driver's acceleration structures of one context.
pub(crate) struct HardwareScene {
    device: wgpu::Device,
    /// Label of this context's driver BLASes.
    blas_label: String,
    /// Label of this context's driver TLAS.
    tlas_label: String,
    /// By geometry slot.
    blases: HashMap<u32, GeometryBlas>,
    /// Builds and updates waiting for the next [`HardwareScene::record`].
    pending: Vec<PendingBlas>,
    /// The instance records as uploaded (by slot): what the TLAS is made of.
    records: Vec<[u32; RECORD_WORDS]>,
    tlas: wgpu::Tlas,
    /// Whether the TLAS must be rebuilt by the next [`HardwareScene::record`].
    tlas_dirty: bool,
}

impl HardwareScene {
    /// No BLASes, and an empty TLAS to be built by the first [`HardwareScene::record`]; the
    /// structures are labelled as `context_id`'s (see [`driver_label_prefix`]).
    pub fn new(device: &wgpu::Device, context_id: u32) -> Self {
        let prefix = driver_label_prefix(context_id);
        let tlas_label = format!("{prefix}TLAS");
        HardwareScene {
            device: device.clone(),
            blas_label: format!("{prefix}BLAS"),
            tlas: create_tlas(
                device,
                64.min(device.limits().max_tlas_instance_count),
                &tlas_label,
            ),
            tlas_label,
            blases: HashMap::new(),
            pending: Vec::new(),
            records: Vec::new(),
            tlas_dirty: true,
        }
    }

    /// The TLAS the traversal binds (built by the first task).
    pub fn tlas(&self) -> &wgpu::Tlas {
        &self.tlas
    }

    /// The geometry in `slot` was (re)built into `triangles` triangles from pool slot
    /// `first_triangle`: a new BLAS, built by the next [`HardwareScene::record`].
    pub fn build(
        &mut self,
        slot: u32,
        first_triangle: u32,
        triangles: u32,
        (updatable, cutout): (bool, bool),
    ) {
        self.blases.remove(&slot);
        self.pending.retain(|p| p.geometry != slot);
        if triangles == 0 {
            // Nothing to hit: the geometry's instances stay out of the TLAS.
            self.tlas_dirty = true;
            return;
        }
        let size = wgpu::BlasTriangleGeometrySizeDescriptor {
            vertex_format: wgpu::VertexFormat::Float32x3,
            vertex_count: triangles * 3,
            index_format: None,
            index_count: None,
            // Cutout geometry's triangles are candidates the ray query confirms by their
            // micro-maps; the others commit inside the driver.
            flags: if cutout {
                wgpu::AccelerationStructureGeometryFlags::empty()
            } else {
                wgpu::AccelerationStructureGeometryFlags::OPAQUE
            },
        };
        let mut flags = wgpu::AccelerationStructureFlags::PREFER_FAST_TRACE;
        if updatable {
            flags |= wgpu::AccelerationStructureFlags::ALLOW_UPDATE;
        }
        let blas = self.device.create_blas(
            &wgpu::CreateBlasDescriptor {
                label: Some(&self.blas_label),
                flags,
                update_mode: if updatable {
                    wgpu::AccelerationStructureUpdateMode::PreferUpdate
                } else {
                    wgpu::AccelerationStructureUpdateMode::Build
                },
            },
            wgpu::BlasGeometrySizeDescriptors::Triangles {
                descriptors: vec![size.clone()],
            },
        );
        self.blases.insert(
            slot,
            GeometryBlas {
                blas,
                size,
                first_triangle,
                updatable,
            },
        );
        self.pending.push(PendingBlas {
            geometry: slot,
            update: false,
        });
        self.tlas_dirty = true;
    }

    /// The geometry in `slot` was refitted (same triangles, moved vertices in place): its BLAS is
    /// updated by the next [`HardwareScene::record`].
    pub fn refit(&mut self, slot: u32) {
        if self.blases.get(&slot).is_some_and(|b| b.updatable)
            && !self.pending.iter().any(|p| p.geometry == slot)
        {
            self.pending.push(PendingBlas {
                geometry: slot,
                update: true,
            });
            self.tlas_dirty = true;
        }
    }

    /// The geometry in `slot` is gone: its BLAS is dropped (wgpu keeps it alive while a
    /// submitted build or TLAS still uses it).
    pub fn remove(&mut self, slot: u32) {
        if self.blases.remove(&slot).is_some() {
            self.pending.retain(|p| p.geometry != slot);
            self.tlas_dirty = true;
        }
    }

    /// The instance record of `slot` as uploaded to the instance table.
    pub fn set_record(&mut self, slot: u32, bytes: &[u8]) {
        let slot = slot as usize;
        if self.records.len() <= slot {
            self.records.resize(slot + 1, [0; RECORD_WORDS]);
        }
        // Byte arrays carry no alignment: read the words one by one.
        for (word, b) in self.records[slot].iter_mut().zip(bytes.chunks_exact(4)) {
            *word = u32::from_ne_bytes([b[0], b[1], b[2], b[3]]);
        }
        self.tlas_dirty = true;
    }

    /// Records the pending BLAS builds and updates (reading the triangle pool `triangles`, as
    /// the software build left it earlier in the same encoder; timed as `driver blas build` in
    /// the `blas build` scope and `driver blas update` in the `blas refit` scope) and, when
    /// anything it depends on changed, the TLAS over every instance record (`driver tlas
    /// build`, scope `tlas build`).
    pub fn record(&mut self, rec: &mut Recorder<'_>, triangles: &wgpu::Buffer) {
        if self.pending.is_empty() && !self.tlas_dirty {
            return;
        }
        let pending = std::mem::take(&mut self.pending);
        for (update, scope, label) in [
            (false, "blas build", "driver blas build"),
            (true, "blas refit", "driver blas update"),
        ] {
            let entries = self.entries(&pending, update, triangles);
            if !entries.is_empty() {
                rec.scope = scope;
                rec.encoder_work(label, |encoder| {
                    encoder.build_acceleration_structures(entries.iter(), std::iter::empty())
                });
            }
        }
        let instances = self.instances();
        if instances.len() > self.tlas.get().len() {
            // The plan refused instance slots past the device's limit.
            let limit = self.device.limits().max_tlas_instance_count;
            let capacity = (instances.len() as u32)
                .next_power_of_two()
                .max(64)
                .min(limit);
            self.tlas = create_tlas(&self.device, capacity, &self.tlas_label);
        }
        let capacity = self.tlas.get().len();
        for (i, instance) in instances.into_iter().enumerate() {
            self.tlas[i] = instance;
        }
        for i in self.records.len().min(capacity)..capacity {
            if self.tlas[i].is_some() {
                self.tlas[i] = None;
            }
        }
        rec.scope = "tlas build";
        let tlas = &self.tlas;
        rec.encoder_work("driver tlas build", |encoder| {
            encoder.build_acceleration_structures(std::iter::empty(), std::iter::once(tlas))
        });
        self.tlas_dirty = false;
    }

    /// The build entries of the `pending` builds (`update == false`) or updates, reading
    /// `triangles`.
    fn entries<'a>(
        &'a self,
        pending: &[PendingBlas],
        update: bool,
        triangles: &'a wgpu::Buffer,
    ) -> Vec<wgpu::BlasBuildEntry<'a>> {
        pending
            .iter()
            .filter(|p| p.update == update)
            .filter_map(|p| self.blases.get(&p.geometry))
            .map(|b| wgpu::BlasBuildEntry {
                blas: &b.blas,
                geometry: wgpu::BlasGeometries::TriangleGeometries(vec![
                    wgpu::BlasTriangleGeometry {
                        size: &b.size,
                        vertex_buffer: triangles,
                        first_vertex: b.first_triangle * 3,
                        vertex_stride: VERTEX_STRIDE,
                        index_buffer: None,
                        first_index: None,
                        transform_buffer: None,
                        transform_buffer_offset: None,
                    },
                ]),
            })
            .collect()
    }

    /// The TLAS instance of every record: `None` where the slot is dead, hidden from every
    /// mask, out of the TLAS, or its geometry has no BLAS (as the software traversal skips them),
    /// and where its transform is singular: the software traversal moves rays into the
    /// instance's space with the inverse, which is not finite there, so nothing of such an
    /// instance is hit, while the driver would hit the flattened triangles.
    fn instances(&self) -> Vec<Option<wgpu::TlasInstance>> {
        self.records
            .iter()
            .enumerate()
            .map(|(slot, w)| {
                let (geometry, mask, participating) = (w[24], w[25], w[26]);
                if participating & 1 == 0 || mask & 0xff == 0 {
                    return None;
                }
                let invertible = w[12..24]
                    .iter()
                    .all(|&bits| f32::from_bits(bits).is_finite());
                if !invertible {
                    return None;
                }
                let blas = self.blases.get(&geometry)?;
                let mut transform = [0f32; 12];
                for (t, &bits) in transform.iter_mut().zip(&w[..12]) {
                    *t = f32::from_bits(bits);
                }
                Some(wgpu::TlasInstance::new(
                    &blas.blas,
                    transform,
                    slot as u32,
                    (mask & 0xff) as u8,
                ))
            })
            .collect()
    }
}

/// An unbuilt TLAS of `capacity` instances.
fn create_tlas(device: &wgpu::Device, capacity: u32, label: &str) -> wgpu::Tlas {
    device.create_tlas(&wgpu::CreateTlasDescriptor {
        label: Some(label),
        max_instances: capacity,
        flags: wgpu::AccelerationStructureFlags::PREFER_FAST_TRACE,
        update_mode: wgpu::AccelerationStructureUpdateMode::Build,
    })
}
