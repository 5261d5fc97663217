//! The hardware service: LCD text and the LED colour of the hardware drone.

use super::*;

impl Swarm {
    fn hw_request(&mut self, op: HardwareOp) -> HardwareRequest {
        let id = self.hw_request_id;
        self.hw_request_id = self.hw_request_id.wrapping_add(1);
        HardwareRequest::new(id, op)
    }

    pub(super) fn lcd(&mut self, text: &str) {
        let w = self.cfg.lcd_width;
        let line0: String = text.chars().take(w).collect();
        let line1: String = text.chars().skip(w).collect();
        for (op, t) in [(LcdOp::WriteLine0, line0), (LcdOp::WriteLine1, line1)] {
            let mut r = self.hw_request(HardwareOp::Lcd);
            r.sub_op = op.to_wire();
            r.text = FixedStr::new(&t);
            self.out.hardware.push(r);
        }
    }

    /// The hardware drone's colour to its LEDs, at most every 100 ms, only on change.
    /// The hardware drone's colour as LED bytes (`None` without a hardware drone).
    pub(super) fn led_bytes(&self) -> Option<[u8; 3]> {
        let idx = self.hw_index?;
        Some(
            self.drones[idx]
                .color
                .map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8),
        )
    }

    pub(super) fn leds(&mut self, now: u64) {
        let Some(bytes) = self.led_bytes() else {
            return;
        };
        if self.hw_last == Some(bytes) || now.saturating_sub(self.hw_last_ns) < LED_PERIOD_NS {
            return;
        }
        for (i, name) in ["red", "green", "blue"].into_iter().enumerate() {
            if self.hw_last.is_some_and(|l| l[i] == bytes[i]) {
                continue;
            }
            let mut r = self.hw_request(HardwareOp::LedSet);
            r.name = FixedStr::new(name);
            r.value = bytes[i];
            self.out.hardware.push(r);
        }
        self.hw_last = Some(bytes);
        self.hw_last_ns = now;
    }
}
