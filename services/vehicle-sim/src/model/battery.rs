//! LiPo battery: open-circuit voltage from state of charge, sag under load,
//! coulomb and energy counting.

/// Open-circuit cell voltage at state of charge 0.0, 0.1, …, 1.0 (a typical
/// LiPo discharge curve).
const OCV_TABLE: [f64; 11] = [
    3.30, 3.60, 3.69, 3.74, 3.78, 3.83, 3.87, 3.93, 4.00, 4.09, 4.20,
];

/// Internal resistance per cell, ohms.
const CELL_RESISTANCE_OHM: f64 = 0.006;

/// A pack of `cells` LiPo cells in series.
#[derive(Debug, Clone, PartialEq)]
pub struct Battery {
    cells: u32,
    capacity_mah: f64,
    initial_fraction: f64,
    consumed_mah: f64,
    consumed_wh: f64,
    current_a: f64,
}

impl Battery {
    /// A pack starting at `initial_fraction` (0..=1) of `capacity_mah`.
    pub fn new(cells: u32, capacity_mah: f64, initial_fraction: f64) -> Self {
        Self {
            cells: cells.max(1),
            capacity_mah,
            initial_fraction: initial_fraction.clamp(0.0, 1.0),
            consumed_mah: 0.0,
            consumed_wh: 0.0,
            current_a: 0.0,
        }
    }

    /// Draw `current_a` for `dt` seconds.
    pub fn step(&mut self, current_a: f64, dt: f64) {
        self.current_a = current_a.max(0.0);
        // A·s → mAh is ÷3.6; W·s → Wh is ÷3600.
        self.consumed_mah += self.current_a * dt / 3.6;
        self.consumed_wh += self.voltage() * self.current_a * dt / 3600.0;
    }

    /// Remaining charge, 0..=1.
    pub fn remaining(&self) -> f64 {
        (self.initial_fraction - self.consumed_mah / self.capacity_mah).clamp(0.0, 1.0)
    }

    /// Terminal voltage under the present load, volts.
    pub fn voltage(&self) -> f64 {
        let soc = self.remaining() * 10.0;
        let i = (soc.floor() as usize).min(9);
        let frac = soc - i as f64;
        let ocv = OCV_TABLE[i] + (OCV_TABLE[i + 1] - OCV_TABLE[i]) * frac;
        let cells = f64::from(self.cells);
        (ocv * cells - self.current_a * CELL_RESISTANCE_OHM * cells).max(0.0)
    }

    /// Present current, amperes.
    pub fn current(&self) -> f64 {
        self.current_a
    }

    /// Charge drawn since start, mAh.
    pub fn consumed_mah(&self) -> f64 {
        self.consumed_mah
    }

    /// Energy drawn since start, watt-hours.
    pub fn consumed_wh(&self) -> f64 {
        self.consumed_wh
    }

    /// Number of cells in series.
    pub fn cells(&self) -> u32 {
        self.cells
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_4s_reads_16_8_volts_at_rest() {
        let b = Battery::new(4, 5200.0, 1.0);
        assert!((b.voltage() - 16.8).abs() < 1e-9);
        assert_eq!(b.remaining(), 1.0);
    }

    #[test]
    fn drains_by_coulomb_count_and_sags_under_load() {
        let mut b = Battery::new(4, 5200.0, 1.0);
        // 15 A for 6 minutes = 1500 mAh.
        for _ in 0..36_000 {
            b.step(15.0, 0.01);
        }
        assert!((b.consumed_mah() - 1500.0).abs() < 0.5);
        assert!((b.remaining() - (1.0 - 1500.0 / 5200.0)).abs() < 1e-3);
        let loaded = b.voltage();
        b.step(0.0, 0.0);
        assert!(b.voltage() > loaded + 0.3);
        assert!(b.consumed_wh() > 20.0);
    }

    #[test]
    fn empty_pack_does_not_go_negative() {
        let mut b = Battery::new(4, 100.0, 0.01);
        for _ in 0..10_000 {
            b.step(50.0, 0.1);
        }
        assert_eq!(b.remaining(), 0.0);
        assert!(b.voltage() >= 0.0);
    }
}
