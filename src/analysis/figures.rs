use crate::render::Recording;
use std::path::{Path, PathBuf};

pub fn write_all(_dir: &Path, _uc: &Recording, _normal: &Recording) -> anyhow::Result<Vec<PathBuf>> {
    Ok(vec![])
}
