// `twinforge doctor`: checks this machine can run twinforge at full speed.
#pragma once

#include <iosfwd>

namespace twinforge::app {

// Prints versions and checks to `out`; returns 0 if all pass, 1 otherwise (with how to fix).
int RunDoctor(std::ostream& out);

}  // namespace twinforge::app
