//! The replay process (below).
