//! Placeholder until the figures land (branch `plot`).
use std::path::{Path, PathBuf};

use crate::error::Result;

pub struct SweepData {
    pub title: String,
    pub parameter: String,
    pub values: Vec<f64>,
    pub exponents: Vec<Vec<f64>>,
    pub sum: Vec<f64>,
    pub expected_sum: Vec<f64>,
    pub per_unit_time: bool,
    pub bifurcation: Vec<(f64, f64)>,
    pub state_name: String,
}

pub fn sweep_figure(_data: &SweepData, _dir: &Path, _stem: &str) -> Result<Vec<PathBuf>> {
    Ok(Vec::new())
}

pub struct GridData {
    pub title: String,
    pub x_name: String,
    pub y_name: String,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub lambda1: Vec<f64>,
    pub per_unit_time: bool,
}

pub fn heat_map(_data: &GridData, _dir: &Path, _stem: &str) -> Result<Vec<PathBuf>> {
    Ok(Vec::new())
}
