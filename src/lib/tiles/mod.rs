//! Paged tile files: the render database on disk, addressed by (level, tx, ty).
