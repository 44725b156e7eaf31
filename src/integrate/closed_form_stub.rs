// TEMPORARY stub while the real closed_form.rs is written.
use nalgebra::Matrix2;
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForcedImpactOscillator;
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExactStatus {
    Ok,
    Chattering,
    Sticking,
}
#[derive(Clone, Copy, Debug)]
pub struct ExactIteration {
    pub state: [f64; 2],
    pub jacobian: Matrix2<f64>,
    pub impacts: u32,
    pub min_impact_velocity: f64,
    pub status: ExactStatus,
}
impl ForcedImpactOscillator {
    pub fn new(_: f64, _: f64, _: f64, _: f64, _: f64) -> Result<Self, String> {
        Err("stub".into())
    }
    pub fn iterate(&self, _y0: [f64; 2]) -> ExactIteration {
        unimplemented!()
    }
}
