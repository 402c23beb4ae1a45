// System 2 of the guard: the deceleration plans, run once per control step.
//
// Perceived each step (added and removed by the orchestrator):
//   alert            the accident predictor's warning (or always present: the "always on" mode)
//   speed(V)         the ego's speed, m/s
//   obstacle_ahead   a vehicle inside the region ahead of the ego
//   ttc(T)           the predictor's time to contact with the neighbour it alerts on, s
//                    (absent in the "always on" mode)
// Parameters (added once): speed_threshold(T) m/s, decel_rate(A) m/s^2, control_hz(F),
//   stop_speed(S) m/s, short_ttc(S) s.
// Mental state: braking(K), the frames of a sustained deceleration still to go.
// Action: .slow_down(Mode) asks for one control frame of deceleration at A
//   (Mode is single or sustained, for the intervention log); .slow_down(hard) one frame at the
//   harder rate the orchestrator holds for it.
//
// The first applicable plan wins, so the order below is the priority.

// Contact is close (a warning whose time to contact is short): brake hard this frame, at any
// speed the ego still moves at. The speed threshold gates only the milder plans below: a slow
// ego about to be hit still gains from stopping sooner. A sustained deceleration in progress
// resumes on the next frame.
+!control : alert & ttc(C) & short_ttc(S) & C < S & speed(V) & stop_speed(Z) & V > Z
    <- .slow_down(hard).

// A sustained deceleration ends early once the ego has (nearly) stopped.
+!control : braking(K) & speed(V) & stop_speed(S) & V < S
    <- -braking(K).

// A sustained deceleration goes on: one frame fewer to go.
+!control : braking(K) & K > 1
    <- -braking(K);
       +braking(K - 1);
       .slow_down(sustained).

// Its last frame.
+!control : braking(K)
    <- -braking(K);
       .slow_down(sustained).

// Warning, an obstacle ahead and high speed: decelerate for N = (v0 / a) * f frames,
// this one included.
+!control : alert & obstacle_ahead & speed(V) & speed_threshold(T) & V > T
            & decel_rate(A) & control_hz(F)
    <- +braking(V / A * F - 1);
       .slow_down(sustained).

// Algorithm 1: warning and high speed, nothing straight ahead: a single-frame slowdown.
+!control : alert & speed(V) & speed_threshold(T) & V > T
    <- .slow_down(single).

// Otherwise the planner keeps control.
+!control
    <- true.
