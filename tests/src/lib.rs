//! Workspace-level tests of the drive: see `tests/`.
