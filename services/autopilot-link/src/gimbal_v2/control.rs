//! Gimbal control ownership (DO_GIMBAL_MANAGER_CONFIGURE): who may aim a camera.

/// Who may control a camera: `(0, 0)` = nobody set.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Control {
    pub primary: (u8, u8),
    pub secondary: (u8, u8),
}

impl Control {
    /// Whether `who` may aim the camera.
    pub fn allows(&self, who: (u8, u8)) -> bool {
        let set = |c: (u8, u8)| c != (0, 0);
        if !set(self.primary) && !set(self.secondary) {
            return true;
        }
        who == self.primary || who == self.secondary
    }

    /// Applies DO_GIMBAL_MANAGER_CONFIGURE params 1–4 from `sender`; `Err` names
    /// the bad parameter.
    pub fn configure(&mut self, params: [f32; 4], sender: (u8, u8)) -> Result<(), &'static str> {
        let mut next = *self;
        let slots: [(&mut u8, u8, u8, &'static str); 4] = [
            (
                &mut next.primary.0,
                sender.0,
                self.primary.0,
                "sysid primary",
            ),
            (
                &mut next.primary.1,
                sender.1,
                self.primary.1,
                "compid primary",
            ),
            (
                &mut next.secondary.0,
                sender.0,
                self.secondary.0,
                "sysid secondary",
            ),
            (
                &mut next.secondary.1,
                sender.1,
                self.secondary.1,
                "compid secondary",
            ),
        ];
        let holds_primary = self.primary == sender;
        let holds_secondary = self.secondary == sender;
        for (i, (slot, own, _, name)) in slots.into_iter().enumerate() {
            let p = params[i];
            if !p.is_finite() || p.fract() != 0.0 || !(-3.0..=255.0).contains(&p) {
                return Err(name);
            }
            match p as i32 {
                -1 => {}
                -2 => *slot = own,
                -3 => {
                    let holds = if i < 2 {
                        holds_primary
                    } else {
                        holds_secondary
                    };
                    if holds {
                        *slot = 0;
                    }
                }
                v => *slot = v as u8,
            }
        }
        *self = next;
        Ok(())
    }
}
