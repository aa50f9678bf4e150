//! What every stage of a run shares: the names users give to option values
//! ([`named`]), progress of long phases ([`progress`]), timings and memory per
//! phase ([`report`]) and the memory budget ([`budget`]).

pub mod budget;
pub mod named;
pub mod progress;
pub mod report;
