#pragma once
// Attitude from two vector observations: Wahba's problem solved by the SVD
// (Markley, "Attitude determination using vector observations and the
// singular value decomposition", J. Astronaut. Sci. 36(3), 1988). The FTM
// thesis (Lee 2021, §3.2.2) uses it as the low-frequency prior that Mahony's
// filter fuses with the gyro; here it also initialises that filter.
//
// With B = Σ w_i b_i r_iᵀ (b: unit vectors in the body, r: the same
// directions in the world) and B = U S Vᵀ, the rotation minimising
// Σ w_i |b_i - A r_i|² is A = U diag(1, 1, det U det V) Vᵀ: the last sign
// makes it a proper rotation (det +1) rather than a reflection.
#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"

namespace proprio::ftm {

// Relative trust in the two observations. Only the ratio matters; with
// noise-free, consistent vectors any positive weights give the same answer.
struct WahbaWeights {
  double accel = 1.0;
  double mag = 1.0;
};

// q_world_body from the accelerometer's specific force and the magnetometer's
// field, both in the body frame, and the same two quantities in the world
// frame (gravity_ref: the specific force at rest, i.e. "up" scaled by g;
// mag_ref: the local Earth field). Magnitudes are ignored (each vector is
// normalised). Errors (invalid_argument): a non-finite or zero vector, a
// non-positive or non-finite weight, or two observations (body or reference)
// closer than about 0.1° to parallel, where heading about them is undefined.
Result<Quat> markley_attitude(const Vec3& accel_body, const Vec3& mag_body, const Vec3& gravity_ref,
                              const Vec3& mag_ref, const WahbaWeights& weights = {});

}  // namespace proprio::ftm
