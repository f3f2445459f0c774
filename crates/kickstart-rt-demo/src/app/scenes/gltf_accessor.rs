//! Checks of a glTF accessor before the gltf crate reads it: its type, and its place in its
//! buffer view and buffer. Shared by the mesh, skin and animation readers.

use gltf::accessor::{DataType, Dimensions};

/// Checks that accessor `a` holds one of `types` in `dims` (`normalized`: integer types must be
/// normalised, as glTF requires of unorm weights).
pub fn typed(
    a: &gltf::Accessor,
    types: &[DataType],
    dims: Dimensions,
    normalized: bool,
) -> Result<(), String> {
    let int_ok = !normalized || a.data_type() == DataType::F32 || a.normalized();
    if types.contains(&a.data_type()) && a.dimensions() == dims && int_ok {
        Ok(())
    } else {
        Err(format!(
            "accessor {} holds {:?} {:?}{}, expected {types:?} {dims:?}{}",
            a.index(),
            a.data_type(),
            a.dimensions(),
            if a.normalized() { " (normalized)" } else { "" },
            if normalized { " (normalized)" } else { "" },
        ))
    }
}

/// Checks that `accessor`'s elements lie inside its buffer view and the view inside its buffer,
/// with checked arithmetic: the gltf crate computes the end of an accessor's data as
/// `offset + stride · (count − 1) + size` unchecked, which a count of 0 or a huge count
/// overflows. Sparse accessors and accessors without a view are left to the reader, which
/// bounds-checks them.
pub fn check_accessor(accessor: &gltf::Accessor, buffers: &[Vec<u8>]) -> Result<(), String> {
    let count = accessor.count();
    if count == 0 {
        return Err(format!("accessor {} has a count of 0", accessor.index()));
    }
    let Some(view) = accessor.view() else {
        return Ok(());
    };
    if accessor.sparse().is_some() {
        return Ok(());
    }
    let size = accessor.size();
    let stride = view.stride().unwrap_or(size).max(size);
    let end = (count - 1)
        .checked_mul(stride)
        .and_then(|x| x.checked_add(size))
        .and_then(|x| x.checked_add(accessor.offset()));
    let buffer_len = buffers.get(view.buffer().index()).map_or(0, Vec::len);
    let view_end = view.offset().checked_add(view.length());
    match (end, view_end) {
        (Some(end), Some(view_end)) if end <= view.length() && view_end <= buffer_len => Ok(()),
        _ => Err(format!(
            "accessor {} ({count} elements of {size} bytes, stride {stride}, offset {}) does not \
             fit its buffer view {} ({} bytes at {} of a {buffer_len}-byte buffer)",
            accessor.index(),
            accessor.offset(),
            view.index(),
            view.length(),
            view.offset()
        )),
    }
}
