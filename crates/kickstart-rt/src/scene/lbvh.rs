//! GPU LBVH (filled by its module's author).
