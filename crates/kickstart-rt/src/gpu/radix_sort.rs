//! GPU radix sort (filled by its module's author).
