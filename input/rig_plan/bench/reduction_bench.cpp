// Times rig reduction and reports the pose error curve (thesis Fig. 3.7) on
// the synthetic characters of the unit tests: how long planning a device from
// the default 18 + 7 kit takes, and how much of the rigid error 5 and 10
// joints remove. Targets (issue 31): <= 10 s for a 100-bone rig with 12
// sample poses; >= 90 % at 5 joints, >= 98 % at 10.
//
//   reduction_bench [samples=12] [seed=1] [fit max iterations] [fit relative tolerance]
// (VERBOSE=1 in the environment lists the joints in greedy order and the device.)
#include <chrono>
#include <ctime>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "proprio/rig_device/kit.hpp"
#include "proprio/rig_plan/rig_reduction.hpp"
// The synthetic characters are the tests'; one definition for both.
#include "../../../tests/unit/input/rig_plan/synthetic_rigs.hpp"
// With the example characters (samples/rig_characters) linked, they are
// measured too.
#ifdef PROPRIO_BENCH_WITH_CHARACTERS
#include "proprio/render/character.hpp"
#include "proprio/rig_characters/examples.hpp"
#endif

namespace {

bool verbose = false;
proprio::rig_plan::ReductionOptions options;
using namespace proprio;
using namespace proprio::rig_plan;

double reduction_at(const Plan& plan, std::size_t joints) {
  if (plan.error_after_joint.empty() || plan.error_rigid <= 0.0) return 0.0;
  const std::size_t k = std::min(joints, plan.error_after_joint.size());
  return 100.0 * (1.0 - plan.error_after_joint[k - 1] / plan.error_rigid);
}

void run(const RigInput& in) {
  const rig_device::Kit kit = rig_device::default_kit();
  const auto t0 = std::chrono::steady_clock::now();
  const std::clock_t c0 = std::clock();
  std::string order;
  auto plan = reduce_rig(in, kit, options, [&](const ReductionProgress& p) {
    if (verbose && p.node >= 0) order += " " + std::to_string(p.iteration) + ":" + in.skeleton.names[static_cast<std::size_t>(p.node)];
  });
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double cpu_seconds = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
  if (!plan) {
    std::printf("%s: %s\n", in.name.c_str(), plan.error().message.c_str());
    return;
  }
  std::printf("%-10s nodes %3zu samples %2zu  wall %6.3f s cpu %6.3f s  joints %2d splitters %d  reduction@5 %6.2f %%  @10 %6.2f %%  "
              "final device %6.2f %%\n",
              in.name.c_str(), in.skeleton.size(), in.samples.size(), seconds, cpu_seconds, plan->joint_count(),
              plan->splitter_count(), reduction_at(*plan, 5), reduction_at(*plan, 10),
              100.0 * (1.0 - plan->error_final / plan->error_rigid));
  std::printf("           curve (%% of rigid error left):");
  for (double e : plan->error_after_joint) std::printf(" %.2f", 100.0 * e / plan->error_rigid);
  std::printf("\n");
  if (verbose) {
    std::printf("           joints in greedy order (pass:node):%s\n           device:", order.c_str());
    for (const DeviceModule& m : plan->modules)
      std::printf(" %s@%s", m.kind.c_str(), in.skeleton.names[static_cast<std::size_t>(m.rig_node)].c_str());
    std::printf("\n");
  }
}

}  // namespace

int main(int argc, char** argv) {
  const int samples = argc > 1 ? std::atoi(argv[1]) : 12;
  const auto seed = static_cast<std::uint64_t>(argc > 2 ? std::atoll(argv[2]) : 1);
  verbose = std::getenv("VERBOSE") != nullptr;
  if (argc > 3) options.fit.max_iterations = std::atoi(argv[3]);
  if (argc > 4) options.fit.relative_tolerance = std::atof(argv[4]);
  if (samples < 1 || samples > 1000) {
    std::fprintf(stderr, "usage: reduction_bench [samples 1..1000] [seed]\n");
    return 2;
  }
  run(synthetic::chain(30, samples, seed));
  run(synthetic::star(5, 6, samples, seed));
  run(synthetic::humanoid(samples, seed));
  run(synthetic::creature(samples, seed));
#ifdef PROPRIO_BENCH_WITH_CHARACTERS
  for (const std::string& name : rig_characters::example_character_names()) {
    auto c = rig_characters::make_example_character(name);
    if (!c) {
      std::printf("%s: %s\n", name.c_str(), c.error().message.c_str());
      continue;
    }
    RigInput in;
    in.name = c->name;
    in.skeleton = c->skeleton;
    in.samples = c->sample_poses;
    in.sample_names = c->sample_names;
    in.area_m2 = render::skin_area_per_node_m2(*c);
    run(in);
  }
#endif
  return 0;
}
