//! How the work spreads: the collective operations between ranks
//! ([`comm`]) and a spare core beside a rank ([`cores`]).

pub mod comm;
pub mod cores;
