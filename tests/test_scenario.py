"""Scenario validation: every bad input is one clear message naming the file and the key."""

import pytest
from helpers import EXAMPLES

from ntncontact.engine.builder import build_model
from ntncontact.io.scenario import ScenarioError, load_config

GOOD = """
[analysis]
kind = "dynamic"
dt = 0.01
t_end = 0.1

[[bodies]]
name = "block"
mesh = { type = "rectangle", width = 1.0, height = 1.0, nx = 2, ny = 2 }
material = { model = "neo_hookean", E = 10.0, nu = 0.3, density = 1.0 }
"""


def write(tmp_path, text):
    path = tmp_path / "case.toml"
    path.write_text(text)
    return path


def test_a_good_scenario_loads_and_builds(tmp_path):
    cfg = load_config(write(tmp_path, GOOD))
    model = build_model(cfg, tmp_path)
    assert model.n_nodes == 9 and model.analysis.dt == 0.01


@pytest.mark.parametrize(
    "replace, expected",
    [
        (("dt = 0.01", "dt = 0.01\ndtt = 2"), "analysis.dtt: unknown key"),
        (("dt = 0.01", 'dt = "fast"'), "analysis.dt"),
        (("nu = 0.3", "nu = 0.5"), "bodies.0.material.nu"),
        (("density = 1.0", "density = -1.0"), "bodies.0.material.density"),
        (('kind = "dynamic"', 'kind = "explicit"'), "analysis.kind"),
        (("E = 10.0, nu = 0.3", "E = 10.0, nu = 0.3, lambda = 1.0, mu = 1.0"), "either E and nu"),
    ],
)
def test_bad_values_name_the_file_and_key(tmp_path, replace, expected):
    path = write(tmp_path, GOOD.replace(*replace))
    with pytest.raises(ScenarioError) as info:
        load_config(path)
    assert str(path) in str(info.value) and expected in str(info.value)


def test_missing_mesh_file_and_unknown_set_are_named(tmp_path):
    text = GOOD.replace('{ type = "rectangle", width = 1.0, height = 1.0, nx = 2, ny = 2 }',
                        '{ type = "gmsh", file = "nowhere.msh" }')
    with pytest.raises(ScenarioError, match="block.*mesh file not found.*nowhere.msh"):
        build_model(load_config(write(tmp_path, text)), tmp_path)
    text = GOOD + '\n[[bodies.supports]]\nset = "bottm"\ny = 0.0\n'
    with pytest.raises(ScenarioError, match="block.*bottm"):
        build_model(load_config(write(tmp_path, text)), tmp_path)


def test_overrides_set_nested_keys_and_reject_bad_paths(tmp_path):
    path = write(tmp_path, GOOD)
    cfg = load_config(path, ["analysis.mass=lumped", "bodies.0.material.E=20.0"])
    assert cfg.analysis.mass == "lumped" and cfg.bodies[0].material.E == 20.0
    with pytest.raises(ScenarioError, match="no item 3"):
        load_config(path, ["bodies.3.name=x"])
    with pytest.raises(ScenarioError, match="unknown key"):
        load_config(path, ["analysis.speed=2"])


def test_missing_file_and_bad_toml(tmp_path):
    with pytest.raises(ScenarioError, match="not found"):
        load_config(tmp_path / "none.toml")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load_config(write(tmp_path, "[analysis\n"))


@pytest.mark.parametrize("path", sorted(EXAMPLES.glob("*.toml")), ids=lambda p: p.name)
def test_every_example_is_a_valid_scenario(path):
    build_model(load_config(path), path.parent)


CONTACT = GOOD + """
[[bodies]]
name = "base"
mesh = { type = "rectangle", width = 1.0, height = 1.0, nx = 2, ny = 2, origin = [0.0, -1.0] }
material = { model = "linear_elastic", E = 10.0, nu = 0.3, density = 1.0 }

[[contact]]
body_1 = "block"
surface_1 = "bottom"
body_2 = "base"
surface_2 = "top"
penalty_normal = 100.0
"""


@pytest.mark.parametrize(
    "replace, expected",
    [
        (('surface_1 = "bottom"', 'surface_1 = "botom"'), "contact.0: .*botom"),
        (('body_2 = "base"\nsurface_2 = "top"', 'body_2 = "block"\nsurface_2 = "bottom"'),
         "same body 'block'.*self-contact"),
        (("penalty_normal = 100.0", "penalty_normal = 100.0\nfriction = -0.1"),
         "contact.0.friction"),
        (("penalty_normal = 100.0", "penalty_normal = -1.0"), "contact.0.penalty_normal"),
        (("penalty_normal = 100.0", "penalty_normal = 100.0\nfriction = 0.2"),
         "penalty_tangential"),
        (('body_1 = "block"', 'body_1 = "blok"'), "no body named 'blok'"),
    ],
)
def test_bad_contact_entries_are_clear_errors(tmp_path, replace, expected):
    path = write(tmp_path, CONTACT.replace(*replace))
    with pytest.raises(ScenarioError, match=expected):
        build_model(load_config(path), tmp_path)


def test_a_contact_scenario_builds_its_interface(tmp_path):
    model = build_model(load_config(write(tmp_path, CONTACT)), tmp_path)
    (ci,) = model.interfaces
    assert ci.name == "interface0" and ci.persistency  # the dynamic default is persistency
    assert ci.interface.surface1.size == 3 and ci.interface.surface2.size == 3


def test_strict_types_keep_integers_for_floats_and_arrays_for_pairs(tmp_path):
    """Strict validation converts nothing, but an integer is a valid float and a TOML array a
    valid pair (E = 10, origin = [0, 1])."""
    text = GOOD.replace("E = 10.0", "E = 10").replace("nx = 2, ny = 2",
                                                       "nx = 2, ny = 2, origin = [0, 1]")
    cfg = load_config(write(tmp_path, text))
    assert cfg.bodies[0].material.E == 10.0 and isinstance(cfg.bodies[0].material.E, float)
    assert cfg.bodies[0].mesh.origin == (0.0, 1.0)
    for bad in ("nx = true", 'nx = "2"', "nx = 2.0"):
        with pytest.raises(ScenarioError, match="bodies.0.mesh.nx = "):
            load_config(write(tmp_path, GOOD.replace("nx = 2", bad)))


def test_errors_are_one_line_naming_each_key_and_value(tmp_path):
    text = GOOD.replace("dt = 0.01", "dt = -1.0").replace("density = 1.0", "density = nan")
    with pytest.raises(ScenarioError) as info:
        load_config(write(tmp_path, text))
    message = str(info.value)
    assert "\n" not in message
    assert "analysis.dt = -1.0" in message and "bodies.0.material.density = nan" in message


def test_utf8_with_a_byte_order_mark_is_read(tmp_path):
    path = tmp_path / "bom.toml"
    path.write_bytes(GOOD.encode("utf-8-sig"))
    assert load_config(path).analysis.dt == 0.01


def test_max_steps_allows_a_longer_run(tmp_path):
    path = write(tmp_path, GOOD.replace("t_end = 0.1", "t_end = 1e6"))
    with pytest.raises(ScenarioError, match="analysis.max_steps = 10000000"):
        load_config(path)
    assert load_config(path, ["analysis.max_steps=100000000"]).analysis.max_steps == 10**8


RING_ON_BLOCK = GOOD + """
[[bodies]]
name = "ring"
mesh.type = "annulus"
mesh.r_inner = 0.5
mesh.r_outer = 1.0
mesh.n_radial = 2
mesh.n_circ = 64
mesh.center = [0.5, LIFT]
material = { model = "neo_hookean", E = 10.0, nu = 0.3, density = 1.0 }

[[contact]]
body_1 = "ring"
surface_1 = "outer"
body_2 = "block"
surface_2 = "top"
penalty_normal = 10.0
"""


@pytest.mark.parametrize("lift, depth", [(1.9, 0.1), (1.7, 0.3)])
def test_bodies_overlapping_at_the_start_are_refused_with_depth_and_place(tmp_path, lift, depth):
    """A ring (closed surface) pushed into the block's top (y = 1) by ``depth``: the lowest ring
    node (0.5, 1 - depth) is reported with its depth below the block's surface."""
    path = write(tmp_path, RING_ON_BLOCK.replace("LIFT", str(lift)))
    with pytest.raises(ScenarioError) as info:
        build_model(load_config(path), tmp_path)
    message = str(info.value)
    assert "contact.0: bodies 'ring' and 'block' overlap at t = 0" in message
    assert f"at (0.5, {1.0 - depth:.6g}) is {depth:.3g} deep inside 'block'" in message


@pytest.mark.parametrize("lift", [2.0, 2.0 + 1e-12, 2.5])
def test_touching_or_separate_bodies_are_not_an_overlap(tmp_path, lift):
    path = write(tmp_path, RING_ON_BLOCK.replace("LIFT", repr(lift)))
    assert len(build_model(load_config(path), tmp_path).interfaces) == 1


@pytest.mark.parametrize("dt, t_end", [(5e-324, 1.0), (float("nan"), 1.0), (0.01, float("inf")),
                                       (2.0, 1.0), (0.0, 1.0)])
def test_analysis_settings_built_in_python_are_checked_too(dt, t_end):
    """The Python API (no scenario file) refuses the same steps, instead of an OverflowError
    in the step count or a run of no step."""
    from ntncontact.engine.model import AnalysisSettings

    with pytest.raises(ValueError, match="analysis"):
        AnalysisSettings(dt=dt, t_end=t_end)
    assert AnalysisSettings(dt=0.5, t_end=0.5).dt == 0.5


DISK = GOOD.replace('{ type = "rectangle", width = 1.0, height = 1.0, nx = 2, ny = 2 }',
                    '{ type = "disk", radius = 0.5, n_circ = 16, n_radial = 2, '
                    'surface_size = 0.1, center = [1.0, 2.0] }')


def test_a_disk_mesh_builds_with_its_sets(tmp_path):
    model = build_model(load_config(write(tmp_path, DISK)), tmp_path)
    mesh = model.bodies[0].mesh
    assert mesh.n_cells == 16 + 2 * 16
    assert {"outer", "bottom", "top", "center", "all"} <= set(mesh.node_sets)
    assert mesh.nodes[mesh.node_sets["bottom"][0]].tolist() == [1.0, 1.5]


@pytest.mark.parametrize("replace, expected", [
    (("n_circ = 16", "n_circ = 12"), "bodies.0.mesh.n_circ = 12: .*multiple of 8"),
    (("surface_size = 0.1", "surface_size = 0.0"), "bodies.0.mesh.surface_size"),
    (("radius = 0.5", "radius = 0.5, nx = 3"), "bodies.0.mesh.nx: unknown key"),
    (("surface_size = 0.1", "surface_size = 0.3"), "bodies.0 .*too large"),
])
def test_bad_disk_keys_are_clear_errors(tmp_path, replace, expected):
    with pytest.raises(ScenarioError, match=expected):
        build_model(load_config(write(tmp_path, DISK.replace(*replace))), tmp_path)


def test_contact_names_must_be_unique(tmp_path):
    """contact.csv's rows and summary.json's penalties are told apart by the interfaces'
    names: a tester's second interface named as the first lost the first's penalty."""
    text = (EXAMPLES / "tilted_blocks.toml").read_text()
    contact = text[text.index("[[contact]]"):]
    assert "\n[[" not in contact.strip()[2:]  # the file's last table
    path = tmp_path / "twice.toml"
    path.write_text(text + "\n" + contact)
    with pytest.raises(ScenarioError, match="contact names must be unique"):
        load_config(path)
