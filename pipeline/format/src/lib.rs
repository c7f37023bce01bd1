//! The dataset motionforge writes, as files: the clip table's schema and row encoding, the shard
//! writer, the manifest, `skeletons.json`, the normalisation files ([`io`]), and the one reader
//! of a built dataset's folder ([`dataset`]).
//!
//! Principal types: [`io::schema::Column`] (every column as one typed value),
//! [`io::parquet::Row`] and [`io::parquet::ShardWriter`], [`io::manifest::Manifest`],
//! [`io::skeletons::SkeletonEntry`] (an entry of `skeletons.json`, as written and as read),
//! [`dataset::OpenShard`] and [`dataset::ShardBatch`] (a shard's named columns, typed),
//! [`dataset::ClipInfo`] (a clip as the readers of a built dataset list it).
//!
//! # A clip's way through this crate
//!
//! Step 5: the clip and its frames become one [`io::parquet::Row`] (positions in the dataset
//! frame, features, plausibility) encoded into its split's shard; the manifest and the
//! normalisation files describe the shards. Every reader reads them back through [`dataset`]:
//! `clips`, `preview`, `export-bvh`, the browser, the report (and the planner through it), the
//! exports, the build's check of its own shards and `bench-build`.

pub mod dataset;
pub mod io;
