//! The dataset motionforge writes, as files: the clip table's schema and row encoding, the shard
//! writer, the manifest, `skeletons.json`, the normalisation files ([`io`]), and the reader of a
//! built dataset's folder ([`dataset`]).
//!
//! Principal types: [`io::schema::Column`] (every column as one typed value),
//! [`io::parquet::Row`] and [`io::parquet::ShardWriter`], [`io::manifest::Manifest`],
//! [`dataset::ClipInfo`] (a clip as the readers of a built dataset list it).
//!
//! # A clip's way through this crate
//!
//! Step 5: the clip and its frames become one [`io::parquet::Row`] (positions in the dataset
//! frame, features, plausibility) encoded into its split's shard; the manifest and the
//! normalisation files describe the shards. `clips`, `preview` and the browser read them back
//! through [`dataset`] (the report, the exports and the planner still use the report's column
//! reader).

pub mod dataset;
pub mod io;
