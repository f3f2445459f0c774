//! Ray batches (filled by its module's author).
