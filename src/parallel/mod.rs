//! How the work spreads: the collective operations between ranks
//! ([`comm`]), one file shared by the ranks ([`file`]), large files
//! around the page cache ([`direct`]) and a spare core beside a rank
//! ([`cores`]).

pub mod comm;
pub mod cores;
pub mod direct;
pub mod file;
