//! Terrain as a triangulated irregular network (placeholder: the TIN helper fills this in).
