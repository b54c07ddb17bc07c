// Tests for the field flags (client/field_flags.h): `compute` and `query` take the same ones — same names, help,
// types and defaults, so the two commands cannot drift apart — every choice left out stays unset for core to make,
// names are read with core's tables, and each bad value or combination is refused naming its flag.
#include "client/field_flags.h"

#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <gtest/gtest.h>

#include "client/cli.h"
#include "client/field_outputs.h"
#include "core/band/band_engine.h"
#include "core/seeds/mesh_seeds.h"
#include "core/stencil.h"

namespace distband {
namespace {

/// What a command's help says about an option.
struct OptionText {
  std::string description, default_value, type;
  int expected = 0;  ///< values it takes (0: a flag)
  friend bool operator==(const OptionText&, const OptionText&) = default;
};

std::map<std::string, OptionText> optionsOf(const CLI::App& command) {
  std::map<std::string, OptionText> options;
  for (const CLI::Option* o : command.get_options())
    options[o->get_name()] = {o->get_description(), o->get_default_str(), o->get_type_name(), o->get_expected_min()};
  return options;
}

/// The names addFieldFlags registers: the field flags.
std::vector<std::string> fieldFlagNames(AssetSeeds assets) {
  CLI::App scratch;
  FieldFlags flags;
  addFieldFlags(&scratch, &flags, assets);
  std::vector<std::string> names;
  for (const CLI::Option* o : scratch.get_options())
    if (o->get_name() != "--help") names.push_back(o->get_name());
  return names;
}

std::set<std::string> onlyIn(const std::map<std::string, OptionText>& a, const std::map<std::string, OptionText>& b) {
  std::set<std::string> names;
  for (const auto& [name, text] : a)
    if (!b.count(name)) names.insert(name);
  return names;
}

std::string helpOf(const std::string& command) {
  std::ostringstream out, err;
  const CliContext ctx{out, err, {}};
  EXPECT_EQ(runDistband({command, "--help"}, ctx), kExitOk) << err.str();
  return out.str();
}

/// The help line that lists `flag` ("  --mesh TEXT    Seed mesh ..."), or "".
std::string helpLine(const std::string& help, const std::string& flag) {
  std::istringstream lines(help);
  for (std::string line; std::getline(lines, line);)
    if (line.rfind("  " + flag + " ", 0) == 0 || line == "  " + flag) return line;
  return {};
}

TEST(FieldFlagsTest, ComputeAndQueryTakeTheSameFieldFlags) {
  std::ostringstream out, err;
  const CliContext ctx{out, err, {}};
  CLI::App app;
  registerAllCommands(app, ctx);
  const std::map<std::string, OptionText> compute = optionsOf(*app.get_subcommand("compute"));
  const std::map<std::string, OptionText> query = optionsOf(*app.get_subcommand("query"));
  const std::map<std::string, OptionText> info = optionsOf(*app.get_subcommand("info"));
  if (!query.count("--mesh")) GTEST_SKIP() << "a build without the service has no query options";

  const std::vector<std::string> field = fieldFlagNames(AssetSeeds::kNo);
  EXPECT_EQ(
      std::set<std::string>(field.begin(), field.end()),
      (std::set<std::string>{"--mesh", "--points", "--points-file", "--volume", "--dims", "--voxel-size", "--origin",
                             "--resolution", "--padding", "--box", "--algorithm", "--stencil", "--mode", "--sign",
                             "--segment", "--limit", "--limit-voxels", "--second-ring", "--deadline", "--spacing",
                             "--labels", "--black-border"}));
  for (const std::string& name : field) {
    ASSERT_TRUE(compute.count(name)) << name;
    ASSERT_TRUE(query.count(name)) << name;
    EXPECT_EQ(compute.at(name), query.at(name)) << name << ": compute says '" << compute.at(name).description
                                                << "', query says '" << query.at(name).description << "'";
    EXPECT_EQ(compute.at(name).default_value, "") << name << ": the CLI leaves the choice to core";
  }
  // What one command has and the other has not: compute's run flag; query's asset seeds and its transport (the
  // connection flags every service command takes, as `info` shows, --encoding and --progress).
  EXPECT_EQ(onlyIn(compute, query), (std::set<std::string>{"--threads"}));
  std::set<std::string> query_own = {"--asset", "--encoding", "--progress"};
  for (const auto& [name, text] : info)
    if (name != "--help") query_own.insert(name);
  EXPECT_EQ(onlyIn(query, compute), query_own);
  // `at` takes the field flags that apply to points, registered by the same functions: the same names and text.
  const std::map<std::string, OptionText> at = optionsOf(*app.get_subcommand("at"));
  for (const char* name : {"--mesh", "--points", "--points-file", "--volume", "--asset", "--voxel-size", "--origin",
                           "--sign", "--limit", "--deadline"}) {
    ASSERT_TRUE(at.count(name)) << name;
    EXPECT_EQ(at.at(name), query.at(name)) << name;
  }
}

TEST(FieldFlagsTest, BothHelpsListTheSameFieldFlags) {
  const std::string compute = helpOf("compute"), query = helpOf("query");
  if (helpLine(query, "--mesh").empty()) GTEST_SKIP() << "a build without the service has no query options";
  for (const std::string& name : fieldFlagNames(AssetSeeds::kNo)) {
    const std::string line = helpLine(compute, name);
    EXPECT_FALSE(line.empty()) << name << " is not in compute's help:\n" << compute;
    EXPECT_EQ(line, helpLine(query, name)) << name;
  }
  EXPECT_FALSE(helpLine(query, "--asset").empty());
  EXPECT_TRUE(helpLine(compute, "--asset").empty());
  EXPECT_TRUE(helpLine(compute, "--signed").empty()) << "one spelling: --sign mask-inside";
}

/// Parses `args` as field flags of a command that takes --asset; returns parseFieldFlags's message.
std::string parse(std::vector<std::string> args, FieldSpec* spec) {
  CLI::App app;
  FieldFlags flags;
  addFieldFlags(&app, &flags, AssetSeeds::kYes);
  std::vector<std::string> reversed(args.rbegin(), args.rend());
  app.parse(reversed);
  return parseFieldFlags(flags, spec);
}

TEST(FieldFlagsTest, ChoicesLeftOutStayUnsetForCore) {
  FieldSpec s;
  ASSERT_EQ(parse({"--mesh", "m.obj", "--resolution", "64"}, &s), "");
  EXPECT_EQ(s.seeds, SeedKind::kMesh);
  EXPECT_EQ(s.source, "m.obj");
  EXPECT_FALSE(s.request.stencil || s.request.mode || s.request.mesh_sign || s.request.second_ring ||
               s.request.algorithm);
  EXPECT_FALSE(s.request.inside_negative);
  EXPECT_TRUE(std::isinf(s.request.limit_world));
  EXPECT_FALSE(s.grid.lattice || s.grid.padding || s.grid.box_min);
  EXPECT_EQ(s.meshGridOptions().resolution, 64);
  EXPECT_FALSE(s.deadline(Interrupter::Clock::now()).has_value());

  ASSERT_EQ(parse({"--points", "1,2,3;4,5,6", "--dims", "8,9,10"}, &s), "");
  EXPECT_TRUE(s.grid.lattice);
  EXPECT_EQ(s.grid.voxel_size, kDefaultVoxelSize);
  EXPECT_EQ(s.grid.origin, (Vec3d{0, 0, 0}));
  EXPECT_EQ(s.points.size(), 2u);

  ASSERT_EQ(parse({"--asset", "volume-00ff", "--sign", "mask-inside", "--limit-voxels", "3", "--deadline", "2"}, &s),
            "");
  EXPECT_TRUE(s.asset && s.grid.lattice && s.request.inside_negative);
  EXPECT_EQ(s.seeds, SeedKind::kVolume);
  EXPECT_TRUE(std::isnan(s.outputLimit())) << "a limit in voxels is known once the grid is";
  EXPECT_TRUE(s.deadline(Interrupter::Clock::now()).has_value());

  // A volume's spacing and origin stay unset unless given: the file's header, else core's default (overrideGeometry).
  ASSERT_EQ(parse({"--volume", "v.nii.gz", "--labels", "--black-border"}, &s), "");
  EXPECT_TRUE(s.request.labels && s.request.black_border);
  EXPECT_FALSE(s.grid.spacing || s.grid.origin_given);
  ASSERT_EQ(parse({"--volume", "v.nrrd", "--spacing", "0.5,0.5,2.5", "--origin", "1,2,3"}, &s), "");
  EXPECT_EQ(*s.grid.spacing, (Vec3d{0.5, 0.5, 2.5}));
  EXPECT_EQ(*s.grid.origin_given, (Vec3d{1, 2, 3}));
  ASSERT_EQ(parse({"--volume", "v.npy", "--voxel-size", "2"}, &s), "");
  EXPECT_EQ(*s.grid.spacing, (Vec3d{2, 2, 2})) << "--voxel-size v means --spacing v,v,v";
  ASSERT_EQ(parse({"--points", "1,1,1", "--dims", "8,8,8", "--spacing", "1,1,3"}, &s), "");
  EXPECT_EQ(*s.grid.spacing, (Vec3d{1, 1, 3}));

  ASSERT_EQ(parse({"--mesh", "m.obj", "--voxel-size", "0.1", "--box", "0,0,0,1,2,3", "--padding", "2"}, &s), "");
  EXPECT_EQ(*s.meshGridOptions().box_max, (Vec3d{1, 2, 3}));
  EXPECT_EQ(s.meshGridOptions().padding_voxels, 2);
}

TEST(FieldFlagsTest, NamesAreReadWithCoresTables) {
  FieldSpec s;
  for (StencilKind k : kStencilKinds) {
    ASSERT_EQ(parse({"--points", "1,1,1", "--dims", "8,8,8", "--stencil", std::string(stencilName(k))}, &s), "");
    EXPECT_EQ(s.request.stencil, k);
  }
  for (PropagationMode m : kPropagationModes) {
    ASSERT_EQ(parse({"--points", "1,1,1", "--dims", "8,8,8", "--mode", std::string(modeName(m))}, &s), "");
    EXPECT_EQ(s.request.mode, m);
  }
  for (SignMethod m : kSignMethods) {
    ASSERT_EQ(parse({"--mesh", "m.obj", "--resolution", "8", "--sign", std::string(signMethodName(m))}, &s), "");
    EXPECT_EQ(s.request.mesh_sign, m);
  }
  ASSERT_EQ(parse({"--mesh", "m.obj", "--resolution", "8", "--mode", "exact-feature"}, &s), "");
  EXPECT_EQ(s.request.mode, PropagationMode::kExact);
  for (FieldAlgorithm a : {FieldAlgorithm::kBand, FieldAlgorithm::kSeparable}) {
    ASSERT_EQ(parse({"--volume", "v.npy", "--algorithm", std::string(algorithmName(a))}, &s), "");
    EXPECT_EQ(s.request.algorithm, a);
  }
  ASSERT_EQ(parse({"--volume", "v.npy", "--algorithm", "auto"}, &s), "");
  EXPECT_FALSE(s.request.algorithm);
}

TEST(FieldFlagsTest, EveryRefusalNamesItsFlag) {
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
      {{"--points", "1,1,1", "--mesh", "m.obj", "--dims", "8,8,8"}, "exactly one seed source"},
      {{"--asset", "bunny", "--voxel-size", "1"}, "--asset 'bunny'"},
      {{"--mesh", "m.obj"}, "exactly one of --resolution N and --voxel-size H"},
      {{"--mesh", "m.obj", "--resolution", "8", "--voxel-size", "1"}, "exactly one of --resolution"},
      {{"--mesh", "m.obj", "--resolution", "1"}, "--resolution must be at least 2"},
      {{"--mesh", "m.obj", "--resolution", "8", "--padding", "-1"}, "--padding must be in"},
      {{"--mesh", "m.obj", "--voxel-size", "-1"}, "--voxel-size must be finite and > 0"},
      {{"--mesh", "m.obj", "--voxel-size", "1", "--origin", "0,0,0"}, "--origin applies to --dims"},
      {{"--mesh", "m.obj", "--voxel-size", "1", "--box", "0,0,0,1,1"}, "--box '0,0,0,1,1'"},
      {{"--volume", "v.npy", "--padding", "2"}, "--padding does not apply to a volume's grid"},
      {{"--points", "1,1,1", "--dims", "8,8,8", "--stencil", "hex"}, "--stencil 'hex'"},
      {{"--points", "1,1,1", "--dims", "8,8,8", "--algorithm", "fast"}, "--algorithm 'fast'"},
      {{"--points", "1,1,1", "--dims", "8,8,8", "--mode", "exact-feature"}, "--mode 'exact-feature'"},
      {{"--points", "1,1,1", "--dims", "8,8,8", "--sign", "parity"}, "--sign 'parity': parity is for meshes"},
      {{"--volume", "v.npy", "--sign", "winding"}, "--sign 'winding'"},
      {{"--mesh", "m.obj", "--resolution", "8", "--sign", "mask-inside"}, "--sign 'mask-inside'"},
      {{"--mesh", "m.obj", "--resolution", "8", "--sign", "signed"}, "--sign 'signed': unknown sign"},
      {{"--points", "1,1,1", "--dims", "8,8,8", "--limit", "0"}, "--limit must be > 0"},
      {{"--points", "1,1,1", "--dims", "8,8,8", "--limit-voxels", "inf"}, "--limit-voxels must be finite"},
      {{"--points", "1,1,1", "--dims", "8,8,8", "--segment", "-1"}, "--segment must be finite"},
      {{"--volume", "v.npy", "--second-ring"}, "--second-ring applies to meshes"},
      {{"--points", "1,1,1", "--dims", "8,8,8", "--deadline", "nan"}, "--deadline must be finite"},
      {{"--volume", "v.nii", "--spacing", "1,1"}, "--spacing '1,1'"},
      {{"--volume", "v.nii", "--spacing", "1,0,1"}, "--spacing '1,0,1': every spacing must be > 0"},
      {{"--volume", "v.nii", "--spacing", "1,1,1", "--voxel-size", "1"}, "--spacing and --voxel-size exclude"},
      {{"--mesh", "m.obj", "--resolution", "8", "--spacing", "1,1,2"}, "--spacing applies to --dims"},
      {{"--mesh", "m.obj", "--resolution", "8", "--labels"}, "--labels applies to volume seeds"},
      {{"--volume", "v.npy", "--black-border"}, "--black-border applies with --labels"},
  };
  for (const auto& [args, expect] : cases) {
    FieldSpec s;
    const std::string message = parse(args, &s);
    EXPECT_NE(message.find(expect), std::string::npos) << "'" << message << "' lacks '" << expect << "'";
  }
}

TEST(FieldFlagsTest, AlgorithmLineIsCoresDescription) {
  FieldPlan plan;
  plan.seeds = SeedKind::kVolume;
  plan.algorithm = FieldAlgorithm::kSeparable;
  plan.limit_world = 3;
  EXPECT_EQ(algorithmLine(plan),
            "algorithm: " + algorithmDescription(FieldAlgorithm::kSeparable, SeedKind::kVolume, true));
  plan.algorithm = FieldAlgorithm::kBand;
  plan.stencil = StencilKind::kFcc12;
  EXPECT_EQ(algorithmLine(plan),
            "algorithm: " + algorithmDescription(FieldAlgorithm::kBand, SeedKind::kVolume, true) + "; stencil fcc12");
}

}  // namespace
}  // namespace distband
