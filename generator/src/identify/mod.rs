pub mod bounded_selection;
pub mod dataset;
pub mod horizon_check;
pub mod horizon_delay;
pub mod pd;
pub mod preprocess;
pub mod response;
pub mod sindy;
