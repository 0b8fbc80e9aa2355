#pragma once
// Synthetic characters for the rig-reduction tests and the timing program: a
// chain, a star, a humanoid-like tree and a ~100-bone many-branch creature,
// with seeded sample poses. Limbs swing more than spine segments and fingers,
// the way animators' sample poses do.
#include <string>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/rig_plan/plan.hpp"

namespace proprio::rig_plan::synthetic {

struct Builder {
  RigInput input;
  std::vector<double> amplitude;  // per node: how far sample poses swing it

  int add(const std::string& name, int parent, const Vec3& t, double area_m2, double amplitude_rad) {
    const int i = input.skeleton.add(name, parent, t);
    input.area_m2.push_back(area_m2);
    amplitude.push_back(amplitude_rad);
    return i;
  }
  int chain(const std::string& prefix, int parent, int count, const Vec3& step, double area_m2, double amplitude_rad) {
    int p = parent;
    for (int i = 0; i < count; ++i) p = add(prefix + std::to_string(i), p, step, area_m2, amplitude_rad);
    return p;
  }
  // Each sample rotates every node by a random axis and an angle up to its
  // amplitude; the root also turns and moves a little.
  RigInput with_samples(int count, std::uint64_t seed) {
    Rng rng(seed);
    const std::size_t n = input.skeleton.size();
    for (int s = 0; s < count; ++s) {
      SkeletonPose pose;
      pose.q_parent_node.resize(n);
      for (std::size_t i = 0; i < n; ++i) {
        Vec3 axis(rng.normal(), rng.normal(), rng.normal());
        if (axis.norm() < 1e-9) axis = Vec3::UnitX();
        const double angle = amplitude[i] * rng.uniform(-1.0, 1.0);
        pose.q_parent_node[i] = (input.skeleton.q_parent_node_rest[i] * so3_exp(axis.normalized() * angle)).normalized();
      }
      pose.t_world_root_m = Vec3(rng.uniform(-0.2, 0.2), rng.uniform(-0.05, 0.05), rng.uniform(-0.2, 0.2));
      input.samples.push_back(std::move(pose));
      input.sample_names.push_back("pose" + std::to_string(s));
    }
    return input;
  }
};

inline RigInput chain(int bones, int samples, std::uint64_t seed) {
  Builder b;
  b.input.name = "chain";
  const int root = b.add("root", -1, Vec3::Zero(), 0.01, 0.3);
  b.chain("bone", root, bones, Vec3(0.0, 0.1, 0.0), 0.01, 0.5);
  return b.with_samples(samples, seed);
}

inline RigInput star(int arms, int bones_per_arm, int samples, std::uint64_t seed) {
  Builder b;
  b.input.name = "star";
  const int root = b.add("root", -1, Vec3::Zero(), 0.02, 0.2);
  for (int a = 0; a < arms; ++a) {
    const double phi = 2.0 * M_PI * a / arms;
    const Vec3 dir(std::cos(phi), 0.0, std::sin(phi));
    b.chain("arm" + std::to_string(a) + "_", root, bones_per_arm, 0.12 * dir, 0.01, 0.5);
  }
  return b.with_samples(samples, seed);
}

// 27 nodes: hips, spine to chest, neck and head, arms with hands, legs with feet.
inline Builder humanoid_builder() {
  Builder b;
  b.input.name = "humanoid";
  const int hips = b.add("hips", -1, Vec3(0.0, 1.0, 0.0), 0.10, 0.2);
  const int spine = b.add("spine", hips, Vec3(0.0, 0.1, 0.0), 0.08, 0.15);
  const int spine1 = b.add("spine1", spine, Vec3(0.0, 0.12, 0.0), 0.08, 0.15);
  const int chest = b.add("chest", spine1, Vec3(0.0, 0.15, 0.0), 0.10, 0.15);
  const int neck = b.add("neck", chest, Vec3(0.0, 0.12, 0.0), 0.01, 0.2);
  const int head = b.add("head", neck, Vec3(0.0, 0.1, 0.0), 0.06, 0.4);
  b.add("head_end", head, Vec3(0.0, 0.18, 0.0), 0.0, 0.0);
  for (int side = -1; side <= 1; side += 2) {
    const std::string s = side < 0 ? "r_" : "l_";
    const int sh = b.add(s + "shoulder", chest, Vec3(0.04 * side, 0.08, 0.0), 0.02, 0.15);
    const int ua = b.add(s + "upper_arm", sh, Vec3(0.14 * side, 0.0, 0.0), 0.05, 0.9);
    const int fa = b.add(s + "forearm", ua, Vec3(0.28 * side, 0.0, 0.0), 0.04, 0.9);
    const int hand = b.add(s + "hand", fa, Vec3(0.25 * side, 0.0, 0.0), 0.015, 0.5);
    b.add(s + "hand_end", hand, Vec3(0.09 * side, 0.0, 0.0), 0.0, 0.0);
    const int th = b.add(s + "thigh", hips, Vec3(0.1 * side, -0.05, 0.0), 0.09, 0.8);
    const int sh2 = b.add(s + "shin", th, Vec3(0.0, -0.45, 0.0), 0.06, 0.9);
    const int foot = b.add(s + "foot", sh2, Vec3(0.0, -0.42, 0.0), 0.02, 0.4);
    const int toe = b.add(s + "toe", foot, Vec3(0.0, -0.06, 0.12), 0.005, 0.3);
    b.add(s + "toe_end", toe, Vec3(0.0, 0.0, 0.05), 0.0, 0.0);
  }
  return b;
}

inline RigInput humanoid(int samples, std::uint64_t seed) { return humanoid_builder().with_samples(samples, seed); }

// About 100 nodes: a body chain with three pairs of legs, a long tail, a
// neck with a head and jaw, and two wings with three fingers each; the small
// parts (toes, fingers, jaw) carry little area.
inline RigInput creature(int samples, std::uint64_t seed) {
  Builder b;
  b.input.name = "creature";
  const int root = b.add("root", -1, Vec3(0.0, 1.0, 0.0), 0.05, 0.1);
  std::vector<int> body;
  int p = root;
  for (int i = 0; i < 10; ++i) {
    p = b.add("body" + std::to_string(i), p, Vec3(0.0, 0.0, 0.15), 0.06, 0.12);
    body.push_back(p);
  }
  for (int pair = 0; pair < 3; ++pair) {
    for (int side = -1; side <= 1; side += 2) {
      const std::string s = "leg" + std::to_string(pair) + (side < 0 ? "r" : "l");
      int q = b.add(s + "_hip", body[static_cast<std::size_t>(1 + 3 * pair)], Vec3(0.12 * side, -0.05, 0.0), 0.02, 0.2);
      q = b.add(s + "_thigh", q, Vec3(0.1 * side, -0.1, 0.0), 0.05, 0.7);
      q = b.add(s + "_shin", q, Vec3(0.0, -0.35, 0.05), 0.03, 0.8);
      q = b.add(s + "_foot", q, Vec3(0.0, -0.35, 0.0), 0.01, 0.4);
      b.add(s + "_toe", q, Vec3(0.0, -0.03, 0.08), 0.003, 0.3);
    }
  }
  int tail = body.front();
  tail = b.chain("tail", root, 17, Vec3(0.0, 0.0, -0.12), 0.015, 0.25);
  (void)tail;
  int neck = b.chain("neck", body.back(), 6, Vec3(0.0, 0.06, 0.08), 0.015, 0.2);
  const int head = b.add("head", neck, Vec3(0.0, 0.05, 0.1), 0.05, 0.4);
  const int jaw = b.add("jaw", head, Vec3(0.0, -0.05, 0.05), 0.01, 0.3);
  b.add("jaw_end", jaw, Vec3(0.0, 0.0, 0.15), 0.0, 0.0);
  b.add("head_end", head, Vec3(0.0, 0.0, 0.2), 0.0, 0.0);
  for (int side = -1; side <= 1; side += 2) {
    const std::string s = side < 0 ? "wing_r" : "wing_l";
    int q = b.add(s + "_root", body[6], Vec3(0.1 * side, 0.1, 0.0), 0.01, 0.2);
    q = b.add(s + "_arm", q, Vec3(0.3 * side, 0.0, 0.0), 0.04, 0.7);
    q = b.add(s + "_fore", q, Vec3(0.4 * side, 0.0, 0.0), 0.03, 0.7);
    const int hand = b.add(s + "_hand", q, Vec3(0.3 * side, 0.0, 0.0), 0.02, 0.4);
    for (int f = 0; f < 3; ++f) {
      const Vec3 dir = Vec3(side * std::cos(0.5 * f), 0.0, -std::sin(0.5 * f));
      b.chain(s + "_finger" + std::to_string(f) + "_", hand, 4, 0.15 * dir, 0.02, 0.25);
    }
  }
  return b.with_samples(samples, seed);
}

}  // namespace proprio::rig_plan::synthetic
