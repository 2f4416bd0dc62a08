//! Studies: runs of furrow's own stages and pipeline that measure it, with their charts and
//! tables: error against run time over the settings ([`tradeoff`]), numerical stability on
//! stiff and extreme cases ([`stability`]), the skin's spatial locality against the whole-skin
//! reference ([`locality`]), muscles against tracking ([`muscles`]), a still rig's correctives
//! against a clip's frames ([`correctives`]), the farm's cost model against a run
//! ([`chunk_cost`]), and the solver benchmarks ([`benchmarks`], with
//! the scaling fits of [`fit`]). This layer sits above the pipeline; it draws with
//! [`crate::render`].

#![warn(missing_docs)]

pub mod benchmarks;
pub mod chunk_cost;
pub mod correctives;
pub mod fit;
pub mod locality;
pub mod muscles;
pub mod preroll;
pub mod stability;
pub mod tradeoff;
