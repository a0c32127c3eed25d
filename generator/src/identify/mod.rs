pub mod dataset;
pub mod pd;
pub mod preprocess;
pub mod sindy;
