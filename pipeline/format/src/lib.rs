//! The dataset motionforge writes, as files: the clip table's schema and row encoding, the shard
//! writer, the manifest, `skeletons.json`, the normalisation files ([`io`]), and the one typed reader
//! of a built dataset's folder that every command reading a dataset uses ([`dataset`]).

pub mod dataset;
pub mod io;
