//! Replies to swarm commands: one per command and drone, queued for publishing.

use super::*;

impl Swarm {
    pub(super) fn reply(
        &mut self,
        cmd: &SwarmCommand,
        drone: u16,
        result: SwarmResult,
        value: i32,
        why: &str,
    ) {
        if self.quiet {
            return;
        }
        let kind = SwarmCommandKind::try_from(cmd.kind).ok();
        self.metrics.reply(kind, result);
        let name = kind.map_or("unknown", SwarmCommandKind::as_str);
        match result {
            SwarmResult::Refused => {
                tracing::info!(
                    drone,
                    kind = name,
                    request = cmd.request_id,
                    reason = why,
                    "refused"
                )
            }
            SwarmResult::Timeout => {
                tracing::warn!(
                    drone,
                    kind = name,
                    request = cmd.request_id,
                    reason = why,
                    "timed out"
                )
            }
            _ => {
                tracing::debug!(drone, kind = name, request = cmd.request_id, result = %result, "reply")
            }
        }
        if self.replies.len() >= MAX_REPLIES_WAITING {
            self.replies.pop_front();
            self.metrics.replies_dropped.inc();
        }
        self.replies.push_back(SwarmReply {
            request_id: cmd.request_id,
            client: cmd.client,
            drone,
            kind: cmd.kind,
            result: result.to_wire(),
            value,
            reason: FixedStr::new(why),
            ..SwarmReply::default()
        });
    }

    pub(super) fn refuse(&mut self, cmd: &SwarmCommand, drone: u16, why: &str) {
        self.reply(cmd, drone, SwarmResult::Refused, 0, why);
    }

    pub(super) fn success(&mut self, cmd: &SwarmCommand, drone: u16) {
        self.reply(cmd, drone, SwarmResult::Success, 0, "");
    }
}
