//! PLACEHOLDER: the host client is being written.
