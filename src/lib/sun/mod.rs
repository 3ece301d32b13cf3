//! Solar position (NREL SPA) for shading and shadow-height.
