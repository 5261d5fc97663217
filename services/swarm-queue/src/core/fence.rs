//! Geofences: the keep-in box sent to the arbiter and its answer or timeout.

use super::*;

impl Swarm {
    /// Sends the keep-in box `b` to the arbiter; the reply waits for its decision.
    pub(super) fn set_fence(&mut self, idx: usize, cmd: &SwarmCommand, b: Aabb, now: u64) {
        let id = self.drones[idx].id;
        match self.geofence_sample(idx, &b) {
            Ok(mut g) => {
                let request_id = self.next_fence_request;
                self.next_fence_request = self.next_fence_request.wrapping_add(1).max(1);
                g.request_id = request_id;
                tracing::debug!(drone = id, request_id, min = ?b.min, max = ?b.max, "geofence sent");
                self.drones[idx].fence_requests.push(FenceRequest {
                    request_id,
                    cmd: *cmd,
                    fence: b,
                    deadline_ns: now + FENCE_ANSWER_TIMEOUT_NS,
                });
                self.out.geofences.push(Box::new(g));
            }
            Err(e) => self.refuse(cmd, id, &e),
        }
    }

    /// The keep-in box `b` (site frame) as the arbiter's geofence for drone `idx`.
    fn geofence_sample(&self, idx: usize, b: &Aabb) -> Result<GeofenceSet, String> {
        if (0..3).any(|i| b.min[i] >= b.max[i]) {
            return Err("geofence box is empty".into());
        }
        let d = &self.drones[idx];
        let site = &self.cfg.site;
        let home_alt = d
            .pose
            .map(|p| p.home_alt_msl)
            .or_else(|| {
                d.status
                    .filter(|s| s.home_valid == 1)
                    .map(|s| f64::from(s.home_alt_msl_m))
            })
            .unwrap_or(site.origin().2);
        let c = d.calibration;
        let mut poly = FencePolygon {
            kind: FenceKind::KeepIn.to_wire(),
            vertex_count: 4,
            ..FencePolygon::default()
        };
        let corners = [
            (b.min[0], b.min[1]),
            (b.max[0], b.min[1]),
            (b.max[0], b.max[1]),
            (b.min[0], b.max[1]),
        ];
        debug_assert!(corners.len() <= MAX_FENCE_VERTICES);
        for (v, (x, y)) in poly.vertices.iter_mut().zip(corners) {
            let (lat, lon) = site.to_geodetic(f64::from(x - c[0]), f64::from(y - c[1]));
            *v = [lat, lon];
        }
        let mut g = GeofenceSet {
            vehicle_id: d.vehicle_id,
            enabled: 1,
            polygon_count: 1,
            source: CommandSource::SwarmQueue.to_wire(),
            ceiling_m: site.alt_rel_of_z(f64::from(b.max[2] - c[2]), home_alt) as f32,
            floor_m: site.alt_rel_of_z(f64::from(b.min[2] - c[2]), home_alt) as f32,
            ..GeofenceSet::default()
        };
        g.polygons[0] = poly;
        g.polygons().map_err(|e| format!("geofence: {e}"))?;
        Ok(g)
    }

    /// Geofences the arbiter did not decide on in time: `Timeout` (the drone's
    /// fence stays what the arbiter last took).
    pub(super) fn expire_fences(&mut self, idx: usize, now: u64) {
        let d = &mut self.drones[idx];
        if d.fence_requests.iter().all(|r| r.deadline_ns > now) {
            return;
        }
        let id = d.id;
        let (late, keep): (Vec<FenceRequest>, Vec<FenceRequest>) = d
            .fence_requests
            .drain(..)
            .partition(|r| r.deadline_ns <= now);
        d.fence_requests = keep;
        for r in late {
            self.reply(
                &r.cmd,
                id,
                SwarmResult::Timeout,
                0,
                "no geofence decision from the arbiter",
            );
        }
    }
}
