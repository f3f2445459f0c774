//! Generational handles: a destroyed or foreign handle is always detected, never aliased.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use crate::error::{Error, HandleKind, Result};

macro_rules! handle_type {
    ($(#[$doc:meta])* $name:ident, $kind:expr) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub struct $name {
            pub(crate) index: u32,
            pub(crate) generation: u32,
            pub(crate) context: u32,
        }

        impl $name {
            /// The slot index of this handle. For instances it is also the index of the
            /// instance's data on the GPU, which a ray hit reports.
            pub fn index(&self) -> u32 {
                self.index
            }
        }

        impl RawHandle for $name {
            const KIND: HandleKind = $kind;
            fn from_parts(index: u32, generation: u32, context: u32) -> Self {
                $name { index, generation, context }
            }
            fn parts(&self) -> (u32, u32, u32) {
                (self.index, self.generation, self.context)
            }
        }
    };
}

handle_type!(
    /// A geometry (one BLAS) registered with a [`crate::GeometryTask`].
    GeometryHandle,
    HandleKind::Geometry
);
handle_type!(
    /// An instance of a geometry placed in the TLAS with an [`crate::InstanceTask`].
    InstanceHandle,
    HandleKind::Instance
);
handle_type!(
    /// The history and intermediate targets of one denoiser.
    DenoisingContextHandle,
    HandleKind::DenoisingContext
);

pub(crate) trait RawHandle: Copy {
    const KIND: HandleKind;
    fn from_parts(index: u32, generation: u32, context: u32) -> Self;
    fn parts(&self) -> (u32, u32, u32);
}

struct Slot<T> {
    generation: u32,
    value: Option<T>,
}

/// A slot map: freed slots are reused with a bumped generation.
pub(crate) struct HandlePool<H: RawHandle, T> {
    context: u32,
    slots: Vec<Slot<T>>,
    /// Free slot indices; the lowest is reused first, so instance data stays dense.
    free: BinaryHeap<Reverse<u32>>,
    _marker: std::marker::PhantomData<H>,
}

impl<H: RawHandle, T> HandlePool<H, T> {
    pub(crate) fn new(context: u32) -> Self {
        HandlePool {
            context,
            slots: Vec::new(),
            free: BinaryHeap::new(),
            _marker: std::marker::PhantomData,
        }
    }

    pub(crate) fn insert(&mut self, value: T) -> H {
        if let Some(Reverse(index)) = self.free.pop() {
            let slot = &mut self.slots[index as usize];
            slot.value = Some(value);
            return H::from_parts(index, slot.generation, self.context);
        }
        let index = self.slots.len() as u32;
        self.slots.push(Slot {
            generation: 1,
            value: Some(value),
        });
        H::from_parts(index, 1, self.context)
    }

    fn invalid(h: H) -> Error {
        let (index, generation, _) = h.parts();
        Error::InvalidHandle {
            kind: H::KIND,
            index,
            generation,
        }
    }

    /// The slot of `h` if it names a live value of this pool.
    fn live_slot(&mut self, h: H) -> Result<&mut Slot<T>> {
        let (index, generation, ctx) = h.parts();
        match self.slots.get_mut(index as usize) {
            Some(slot) if ctx == self.context && slot.generation == generation => Ok(slot),
            _ => Err(Self::invalid(h)),
        }
    }

    pub(crate) fn get(&self, h: H) -> Result<&T> {
        let (index, generation, ctx) = h.parts();
        match self.slots.get(index as usize) {
            Some(slot) if ctx == self.context && slot.generation == generation => {
                slot.value.as_ref().ok_or_else(|| Self::invalid(h))
            }
            _ => Err(Self::invalid(h)),
        }
    }

    pub(crate) fn get_mut(&mut self, h: H) -> Result<&mut T> {
        self.live_slot(h)?
            .value
            .as_mut()
            .ok_or_else(|| Self::invalid(h))
    }

    pub(crate) fn remove(&mut self, h: H) -> Result<T> {
        let slot = self.live_slot(h)?;
        let value = slot.value.take().ok_or_else(|| Self::invalid(h))?;
        slot.generation = slot.generation.wrapping_add(1).max(1);
        let (index, _, _) = h.parts();
        self.free.push(Reverse(index));
        Ok(value)
    }

    pub(crate) fn handles(&self) -> Vec<H> {
        self.slots
            .iter()
            .enumerate()
            .filter(|(_, s)| s.value.is_some())
            .map(|(i, s)| H::from_parts(i as u32, s.generation, self.context))
            .collect()
    }

    /// Slots ever used (live or free): one past the highest index handed out.
    pub(crate) fn slot_count(&self) -> u32 {
        self.slots.len() as u32
    }
}

/// Identifies one built GPU task until it is marked completed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct GpuTaskHandle(pub(crate) u64);

impl GpuTaskHandle {
    /// The serial number of the task (1 for the first built by a context).
    pub fn serial(&self) -> u64 {
        self.0
    }
}
