//! The database directory: `manifest.json` plus layer files.
