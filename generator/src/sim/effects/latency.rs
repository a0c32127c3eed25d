//! The command delay line: channel i of the command applied at time s is the last command given
//! at or before s − dᵢ (zero-order hold at the sample rate, switched at the RK4 substep where
//! the delayed switch falls, so delays resolve to one substep). Before the first delayed
//! command arrives the autopilot holds the hover command 0.

#[derive(Clone, Debug)]
pub struct DelayLine {
    delays: [f64; 4],
    /// (time given, command), oldest first.
    history: std::collections::VecDeque<(f64, [f64; 4])>,
}

/// Tolerance of the time comparisons, s (far below any substep).
const EPS: f64 = 1e-9;

impl DelayLine {
    pub fn new(delays: [f64; 4]) -> Self {
        Self {
            delays,
            history: Default::default(),
        }
    }

    pub fn clear(&mut self) {
        self.history.clear();
    }

    /// Record the command given at time t.
    pub fn push(&mut self, t: f64, u: [f64; 4]) {
        self.history.push_back((t, u));
    }

    /// The command applied at time s; forgets what can no longer be needed (s only increases).
    pub fn at(&mut self, s: f64) -> [f64; 4] {
        let mut out = [0.0; 4];
        for i in 0..4 {
            let due = s - self.delays[i] + EPS;
            out[i] = self
                .history
                .iter()
                .rev()
                .find(|(t, _)| *t <= due)
                .map(|(_, u)| u[i])
                .unwrap_or(0.0);
        }
        let max_delay = self.delays.iter().cloned().fold(0.0, f64::max);
        // Keep the newest entry that is due for the longest delay, and everything after it.
        while self.history.len() >= 2 && self.history[1].0 <= s - max_delay + EPS {
            self.history.pop_front();
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delays_per_channel() {
        let mut d = DelayLine::new([0.0, 0.1, 0.2, 0.0]);
        d.push(0.0, [1.0, 1.0, 1.0, 1.0]);
        assert_eq!(d.at(0.0), [1.0, 0.0, 0.0, 1.0]);
        assert_eq!(d.at(0.1), [1.0, 1.0, 0.0, 1.0]);
        d.push(0.15, [2.0, 2.0, 2.0, 2.0]);
        assert_eq!(d.at(0.15), [2.0, 1.0, 0.0, 2.0]);
        assert_eq!(d.at(0.2), [2.0, 1.0, 1.0, 2.0]);
        assert_eq!(d.at(0.25), [2.0, 2.0, 1.0, 2.0]);
        assert_eq!(d.at(0.35), [2.0, 2.0, 2.0, 2.0]);
        assert_eq!(d.history.len(), 1);
    }
}
