//! Vertex pulling (filled by its module's author).
