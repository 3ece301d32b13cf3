//! `dbms ingest`: a DEM and an orthophoto registered onto one database grid.
