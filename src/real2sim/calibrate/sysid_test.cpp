#include "real2sim/calibrate/sysid.h"

#include <gtest/gtest.h>

#include "core/error.h"

namespace twinforge::real2sim {
namespace {

// A paddle on a slide knocks a box along the floor; the box slides until friction stops it.
// The floor's friction is low: MuJoCo takes the larger of the two, so the box's own decides.
constexpr char kPush[] = R"(
<mujoco>
  <option timestep="0.002"/>
  <worldbody>
    <geom name="floor" type="plane" size="2 2 0.1" friction="0.05"/>
    <body name="pusher" pos="-0.2 0 0.05">
      <joint name="slide" type="slide" axis="1 0 0" damping="40"/>
      <geom name="paddle" type="box" size="0.01 0.1 0.04" mass="1"/>
    </body>
    <body name="box" pos="0 0 0.05">
      <freejoint name="box"/>
      <geom name="box" type="box" size="0.05 0.05 0.05" mass="0.5" friction="0.35"/>
    </body>
    <body name="arm" pos="0 0.6 0.3">
      <joint name="hinge" type="hinge" axis="0 1 0" damping="0.3"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" mass="0.4" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
  <actuator><position name="push" joint="slide" kp="3000"/></actuator>
</mujoco>)";

// The paddle driven to 0.16 m, quickly (10 ms per step, 1.5 s): the box and the hinge measured.
Trajectory Record(const mjModel* m) {
  Trajectory t;
  t.qpos0.assign(m->qpos0, m->qpos0 + m->nq);
  t.qpos0[m->jnt_qposadr[mj_name2id(m, mjOBJ_JOINT, "hinge")]] = 0.8;  // let go from 0.8 rad
  t.qvel0.assign(m->nv, 0.0);
  t.substeps = 5;
  t.measured = {m->jnt_qposadr[mj_name2id(m, mjOBJ_JOINT, "box")],
                m->jnt_qposadr[mj_name2id(m, mjOBJ_JOINT, "hinge")]};
  for (int k = 0; k < 150; ++k) t.ctrl.push_back({k < 3 ? 0.06 * k : 0.16});
  t.positions = Replay(m, t);
  return t;
}

TEST(Sysid, RecoversAKnownFrictionAndDampingFromAPush) {
  sim::ModelPtr model = sim::LoadModelFromText(kPush);
  const std::vector<Trajectory> real = {Record(model.get())};
  // The box slid: the friction is in the trajectory.
  ASSERT_GT(real[0].positions.back()[0], 0.05);
  const std::vector<PhysicalParameter> unknown = {
      {PhysicalParameter::Kind::kGeomFriction, "box", 0.05, 2.0},
      {PhysicalParameter::Kind::kJointDamping, "hinge", 0.01, 10.0}};
  for (const auto method : {SysidOptions::Method::kGradient, SysidOptions::Method::kCmaEs}) {
    // The twin's guesses: friction 0.8 (true 0.35), damping 1.0 (true 0.3).
    SetParameter(model.get(), unknown[0], 0.8);
    SetParameter(model.get(), unknown[1], 1.0);
    const double before = TrajectoryError(model.get(), real);
    SysidOptions options;
    options.method = method;
    options.iterations = method == SysidOptions::Method::kGradient ? 60 : 30;
    const SysidResult r = IdentifyParameters(model.get(), unknown, real, options);
    SCOPED_TRACE(method == SysidOptions::Method::kGradient ? "gradient" : "cma-es");
    EXPECT_NEAR(r.values[0], 0.35, 0.35 * 0.05);
    EXPECT_NEAR(r.values[1], 0.3, 0.3 * 0.05);
    EXPECT_LT(r.error.back(), 0.01 * before);
    EXPECT_DOUBLE_EQ(GetParameter(model.get(), unknown[0]), r.values[0]);
  }
}

TEST(Sysid, MassAndActuatorGainAreSetWhereMujocoReadsThem) {
  sim::ModelPtr m = sim::LoadModelFromText(kPush);
  const PhysicalParameter mass{PhysicalParameter::Kind::kBodyMass, "box"};
  const double inertia = m->body_inertia[3 * mj_name2id(m.get(), mjOBJ_BODY, "box")];
  SetParameter(m.get(), mass, 1.0);
  EXPECT_DOUBLE_EQ(GetParameter(m.get(), mass), 1.0);
  EXPECT_DOUBLE_EQ(m->body_inertia[3 * mj_name2id(m.get(), mjOBJ_BODY, "box")], 2 * inertia);
  const PhysicalParameter kp{PhysicalParameter::Kind::kActuatorGain, "push"};
  SetParameter(m.get(), kp, 500);
  EXPECT_DOUBLE_EQ(m->actuator_gainprm[0], 500);
  EXPECT_DOUBLE_EQ(m->actuator_biasprm[1], -500);
  EXPECT_THROW(GetParameter(m.get(), {PhysicalParameter::Kind::kJointDamping, "nothing"}),
               core::ConfigError);
}

TEST(Sysid, AForceLimitCapsWhatTheActuatorPushes) {
  sim::ModelPtr m = sim::LoadModelFromText(kPush);
  const PhysicalParameter force{PhysicalParameter::Kind::kActuatorForce, "push"};
  EXPECT_EQ(GetParameter(m.get(), force), HUGE_VAL);  // not limited in the model
  SetParameter(m.get(), force, 5);
  EXPECT_DOUBLE_EQ(GetParameter(m.get(), force), 5);
  sim::DataPtr d = sim::MakeData(m.get());
  d->ctrl[0] = 0.2;  // kp 3000 x 0.2 m: 600 N unlimited
  mj_step(m.get(), d.get());
  EXPECT_NEAR(d->actuator_force[0], 5, 1e-9);
}

}  // namespace
}  // namespace twinforge::real2sim
