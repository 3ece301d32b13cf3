//! Cast-shadow masks over a height field for a sun direction.
