pub mod dataset;
pub mod preprocess;
