//! # mss-io (skeleton)
