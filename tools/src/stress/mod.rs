//! The stability sweep (issue 9): generated stress scenes ([`scenes`]) rendered and traced by
//! every method, each point counted as correct, a silent failure (wrong closest hit, leak, NaN or
//! infinite pixel, crash, hang) or a clear refusal.

pub mod scenes;
