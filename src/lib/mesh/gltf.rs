//! glTF 2.0 binary (placeholder: the glTF helper fills this in).
