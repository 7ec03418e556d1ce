#include "learn/residual.h"

#include <algorithm>

namespace twinforge::learn {

void ToUnitAction(const sim::Action& action, const sim::ActionLimits& limits,
                  const sim::GripperState& gripper, float* unit) {
  const sim::EeCommand command = sim::DecodeAction(action, limits, gripper);
  std::fill_n(unit, sim::kContinuousActionDim, 0.0f);
  if (action.mode == sim::ActionMode::kDiscrete) {
    const int i = action.index;
    if (i < 12) unit[i / 2] = i % 2 == 0 ? 1.0f : -1.0f;
  } else {
    for (int k = 0; k < 3; ++k) {
      unit[k] = float(std::clamp(action.value[k] / limits.translation, -1.0, 1.0));
      unit[3 + k] = float(std::clamp(action.value[3 + k] / limits.rotation, -1.0, 1.0));
    }
  }
  unit[6] = float(2 * command.closure - 1);
}

sim::Action FromUnitAction(const float* unit, const sim::ActionLimits& limits) {
  std::array<double, sim::kContinuousActionDim> v{};
  for (int k = 0; k < 3; ++k) {
    v[k] = std::clamp(double(unit[k]), -1.0, 1.0) * limits.translation;
    v[3 + k] = std::clamp(double(unit[3 + k]), -1.0, 1.0) * limits.rotation;
  }
  v[6] = std::clamp(double(unit[6]), -1.0, 1.0);
  return sim::Action::Continuous(v);
}

}  // namespace twinforge::learn
