//! The generated sample scene (`dbms sample`).
