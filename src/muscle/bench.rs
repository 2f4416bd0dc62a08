//! `furrow bench fit` (filled in below).
