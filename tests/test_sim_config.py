import copy
import dataclasses

import pytest

from parcelfit import ParcelfitError
from parcelfit.config import load_yaml
from parcelfit.sim.mujoco import (
    bundled_consignment_names,
    bundled_rig_names,
    load_consignment,
    load_rig,
)
from parcelfit.sim.mujoco.consignment import parse_consignment
from parcelfit.sim.mujoco.contact import contact_params, realised_stiffness
from parcelfit.sim.mujoco.rig import parse_rig
from parcelfit.sim.params import CATALOGUE, parameter, parameters_for, parse_assignments, resolve


def test_bundled_rigs_and_consignments():
    assert bundled_rig_names() == ["E1", "E2a", "E2b", "E3"]
    assert bundled_consignment_names() == ["BW", "KP", "KPBW", "PB"]
    e3 = load_rig("E3")
    assert e3.drive_speeds(1) == {"main": 1.56, "strip": 1.64}
    assert e3.drive_speeds(2)["main"] == 1.86
    assert load_rig("E1").drive_speeds(3)["belt2"] == 1.57
    assert load_rig("E2b").surface("splitter").extra["swivel"] == 30
    assert e3.surface("strips").top - e3.surface("main").top == pytest.approx(0.02)
    kpbw = load_consignment("KP/BW")
    assert (kpbw.mass, kpbw.outer, kpbw.content_kind) == (0.14, (0.275, 0.20, 0.02), "rigid")
    assert load_consignment("PB").content_kind == "soft"
    with pytest.raises(ParcelfitError, match=r"unknown rig 'E9'.*E1, E2a, E2b, E3"):
        load_rig("E9")


def _e3_doc():
    return copy.deepcopy(load_yaml(load_rig("E3").source))


@pytest.mark.parametrize(
    ("change", "pattern"),
    [
        (lambda d: d.update(lenght=1), r"top level: unknown key 'lenght'"),
        (
            lambda d: d["surfaces"][0].update(material="wood"),
            r"surfaces\[0\]\.material: unknown material 'wood'",
        ),
        (lambda d: d["surfaces"][0].update(type="chute"), r"unknown surface type 'chute'"),
        (lambda d: d["surfaces"][1].pop("pitch"), r"surfaces\[1\]: missing required key 'pitch'"),
        (lambda d: d["surfaces"][0].update(drive="nope"), r"drive 'nope' has no speed in setting"),
        (lambda d: d["start"].update(surface="floor"), r"start\.surface names no surface: 'floor'"),
        (lambda d: d["light_barriers"].pop(), r"exactly two light barriers"),
        (lambda d: d["surfaces"][0].update(width=-1), r"surfaces\[0\]\.width: -1 is outside"),
        (
            lambda d: d["walls"][0].update(**{"from": [0, 0, 0]}),
            r"walls\[0\]\.from: expected a point",
        ),
        (
            lambda d: d["speeds"].update({0: {"main": 1}}),
            r"speed setting 0 must be an integer from 1 to 1000",
        ),
        (
            lambda d: d.update(step_refinement=1.5),
            r"step_refinement: expected a whole number",
        ),
        (lambda d: d.update(step_refinement=0), r"step_refinement: 0 is out of range"),
        (
            lambda d: d["surfaces"][0].update(nose_radius=-0.01),
            r"surfaces\[0\]\.nose_radius: -0\.01 is outside",
        ),
        (
            lambda d: d["surfaces"][1].update(length=0.3, nose_radius=0.15),
            r"surfaces\[1\]\.nose_radius: nose_radius 0\.15 m leaves no flat top on a surface "
            r"0\.3 m long",
        ),
    ],
)
def test_bad_rig_files(change, pattern):
    doc = _e3_doc()
    change(doc)
    with pytest.raises(ParcelfitError, match=pattern) as info:
        parse_rig(doc, "my_rig.yaml")
    assert str(info.value).startswith("my_rig.yaml")


def test_rollers_have_no_drum_ends():
    doc = copy.deepcopy(load_yaml(load_rig("E2a").source))
    assert [s.get("nose_radius") for s in doc["surfaces"]] == [0.02, None, 0.02]
    doc["surfaces"][1]["nose_radius"] = 0.02
    with pytest.raises(ParcelfitError, match=r"surfaces\[1\]: unknown key 'nose_radius'"):
        parse_rig(doc, "my_rig.yaml")
    doc["surfaces"][1].pop("nose_radius")
    doc["surfaces"][0].pop("nose_radius")
    assert parse_rig(doc, "my_rig.yaml").surface("infeed").nose_radius == 0.0


def test_bad_consignment_files():
    good = {
        "name": "X",
        "mass": 0.1,
        "outer": [0.3, 0.2, 0.02],
        "content": {"kind": "rigid", "size": [0.2, 0.1, 0.02]},
    }
    parse_consignment(good, "c.yaml")
    bad = copy.deepcopy(good)
    bad["content"]["size"] = [0.3, 0.1, 0.02]
    with pytest.raises(ParcelfitError, match=r"c\.yaml: content\.size: content .* does not fit"):
        parse_consignment(bad, "c.yaml")
    bad = copy.deepcopy(good)
    bad["content"]["kind"] = "liquid"
    with pytest.raises(ParcelfitError, match="unknown content kind 'liquid'"):
        parse_consignment(bad, "c.yaml")
    with pytest.raises(ParcelfitError, match=r"expected \[length, width, height\]"):
        parse_consignment({**good, "outer": [300, 200]}, "c.yaml")
    # the shell a type chooses (a scene's choices but "auto")
    assert parse_consignment({**good, "shell": "full"}, "c.yaml").shell == "full"
    for bad in ("auto", "floppy"):
        with pytest.raises(
            ParcelfitError, match=rf"c\.yaml: shell: unknown shell degrees of freedom '{bad}'"
        ):
            parse_consignment({**good, "shell": bad}, "c.yaml")
    # its grid of cells: three whole numbers, with an interpolated shell of its own
    cells = parse_consignment({**good, "shell": "trilinear", "shell_cells": [4, 3, 1]}, "c.yaml")
    assert cells.shell_cells == (4, 3, 1)
    assert parse_consignment(good, "c.yaml").shell_cells == (1, 1, 1)
    for shell, value, pattern in (
        (None, [4, 4, 1], "shell_cells: shell_cells needs an interpolated shell"),
        ("full", [4, 4, 1], "shell_cells: shell_cells needs an interpolated shell"),
        ("trilinear", [4, 4], "shell_cells: shell cells must be three whole numbers"),
        ("trilinear", [4.5, 4, 1], "shell_cells: shell cells must be three whole numbers"),
        ("trilinear", [4, 13, 1], r"shell_cells\[1\]: 13 is outside \[1, 12\]"),
    ):
        doc = {**good, "shell_cells": value} | ({"shell": shell} if shell else {})
        with pytest.raises(ParcelfitError, match=rf"c\.yaml: {pattern}"):
            parse_consignment(doc, "c.yaml")


def test_a_type_may_choose_its_shell_and_a_scene_still_overrides_it():
    """The rigid-content types' files take a trilinear shell over 4 x 4 x 1 cells, PB leaves it
    to the scene's default (full around a soft content); a scene's ``shell_dof`` beats the
    type's choice and then takes one cell unless it gives ``shell_cells`` too, and the choice
    reaches the MuJoCo model (5 x 5 x 2 nodes, 8 for one trilinear cell, 27 for the quadratic
    shell). Bad choices: `test_bad_consignment_files`."""
    import mujoco

    from parcelfit.sim.mujoco.options import SceneOptions
    from parcelfit.sim.mujoco.scene import build_scene

    types = {n: load_consignment(n) for n in ("BW", "KPBW", "KP", "PB")}
    assert {n: (c.shell, c.shell_cells) for n, c in types.items()} == {
        "BW": ("trilinear", (4, 4, 1)),
        "KPBW": ("trilinear", (5, 5, 1)),
        "KP": ("trilinear", (4, 4, 1)),
        "PB": (None, (1, 1, 1)),
    }
    auto = SceneOptions()
    kp, pb = types["KP"], types["PB"]
    assert auto.shell_of(kp) == ("trilinear", (4, 4, 1))
    assert auto.shell_of(pb) == ("full", (1, 1, 1))
    assert SceneOptions(shell_dof="quadratic").shell_of(kp) == ("quadratic", (1, 1, 1))
    assert SceneOptions(shell_dof="trilinear").shell_of(kp) == ("trilinear", (1, 1, 1))
    assert SceneOptions(shell_cells=(2, 3, 1)).shell_of(kp) == ("trilinear", (2, 3, 1))
    assert SceneOptions(shell_dof="full", shell_cells=(2, 3, 1)).shell_of(kp) == ("full", (1, 1, 1))
    # a type without a shell of its own: quadratic, one cell, under the scene's default
    plain = dataclasses.replace(kp, shell=None, shell_cells=(1, 1, 1))
    assert auto.shell_of(plain) == ("quadratic", (1, 1, 1))
    # an interpolated shell keeps the interpolated step, the full shell its own
    assert auto.step_for(kp.soft, None, kp.shell) == pytest.approx(1 / 2400)
    assert auto.step_for(False, None, "full") == pytest.approx(1 / 1200)

    def nodes(options):
        xml = build_scene(load_rig("E3"), kp, kp.parameter_values(), 1, options).xml
        model = mujoco.MjModel.from_xml_string(xml)
        return model.flex_nodenum[0], tuple(model.flex_cellnum[0])

    assert nodes(auto) == (50, (4, 4, 1))
    assert nodes(SceneOptions(shell_dof="trilinear")) == (8, (1, 1, 1))
    assert nodes(SceneOptions(shell_dof="quadratic")) == (27, (1, 1, 1))
    assert nodes(SceneOptions(shell_cells=(2, 3, 1))) == (24, (2, 3, 1))


def test_a_types_own_defaults_sit_between_the_catalogue_and_the_user():
    from parcelfit.runs import TestCase
    from parcelfit.sim.mujoco import MujocoSimulator

    bw, kpbw = load_consignment("BW"), load_consignment("KPBW")
    assert dict(bw.parameters) == {"mu_d_BePa": 0.565, "mu_d_MePa": 0.350}
    catalogue = resolve("rigid")
    own = bw.parameter_values()
    assert (own["mu_d_BePa"], own["mu_d_MePa"]) == (0.565, 0.350)
    assert {k: v for k, v in own.items() if not k.startswith("mu_d_")} == {
        k: v for k, v in catalogue.items() if not k.startswith("mu_d_")
    }
    assert bw.parameter_values({"mu_d_BePa": 0.4})["mu_d_BePa"] == 0.4
    assert bw.parameter_values(si_values={"mu_d_MePa": 0.2})["mu_d_MePa"] == 0.2
    assert kpbw.parameter_values()["mu_d_BePa"] == 0.300
    # a run that leaves them out gets them; a given value wins
    sim = MujocoSimulator()
    xml = sim.scene({}, TestCase("E3", "BW", 1)).xml
    assert 'friction="0.565 ' in xml and 'friction="0.35 ' in xml
    xml = sim.scene({"mu_d_BePa": 0.4}, TestCase("E3", "BW", 1)).xml
    assert 'friction="0.4 ' in xml and 'friction="0.565' not in xml

    good = {
        "name": "X",
        "mass": 0.1,
        "outer": [0.3, 0.2, 0.02],
        "content": {"kind": "rigid", "size": [0.2, 0.1, 0.02]},
    }
    assert parse_consignment(good, "c.yaml").parameter_values() == catalogue
    with pytest.raises(ParcelfitError, match=r"c\.yaml: parameters\.mu_x: unknown parameter"):
        parse_consignment({**good, "parameters": {"mu_x": 0.3}}, "c.yaml")
    with pytest.raises(
        ParcelfitError, match=r"c\.yaml: parameters\.mu_d_BePa: mu_d_BePa = 5 is outside"
    ):
        parse_consignment({**good, "parameters": {"mu_d_BePa": 5}}, "c.yaml")
    with pytest.raises(ParcelfitError, match=r"parameters\.E_Co: .*does not apply to rigid"):
        parse_consignment({**good, "parameters": {"E_Co": 0.1}}, "c.yaml")


def test_catalogue_counts_units_and_published_values():
    assert len(parameters_for("rigid")) == 16
    assert len(parameters_for("soft")) == 18
    published = {p.name for p in CATALOGUE if p.published}
    assert published == {
        "k_CoPa",
        "k_MePa",
        "mu_d_BePa",
        "mu_d_MePa",
        "mu_s_MePa",
        "E_Pa",
        "E_Co",
        "zeta_Co",
    }
    assert parameter("k_MePa").range_for("rigid").default == 611
    assert parameter("E_Pa").range_for("soft").low == 50
    assert parameter("E_Co").range_for("soft").default == 0.08
    si = resolve("rigid", user_values={"k_CoPa": 250, "E_Pa": 506})
    assert si["k_CoPa"] == 250e3 and si["E_Pa"] == 506e6
    assert resolve("rigid", si_values={"t_Pa": 4e-4})["t_Pa"] == pytest.approx(4e-4)


def test_bad_parameters():
    with pytest.raises(
        ParcelfitError, match=r"unknown parameter 'mu_d_bePa'.*did you mean 'mu_d_BePa'"
    ):
        resolve("rigid", user_values={"mu_d_bePa": 0.4})
    with pytest.raises(ParcelfitError, match="E_Co does not apply to rigid"):
        resolve("rigid", user_values={"E_Co": 0.1})
    with pytest.raises(
        ParcelfitError, match=r"mu_d_BePa = 5 is outside its physical range \[0, 2\]"
    ):
        resolve("rigid", user_values={"mu_d_BePa": 5})
    assert parse_assignments(["mu_d_BePa=0.4", " E_Pa = 800"]) == {"mu_d_BePa": 0.4, "E_Pa": 800.0}
    with pytest.raises(ParcelfitError, match="write NAME=VALUE"):
        parse_assignments(["mu_d_BePa:0.4"])


def test_contact_mapping_round_trip_and_impedance_choice():
    cp = contact_params(5e5, 208, 1 / 1.6e-4, 1.0, 1 / 600)
    assert realised_stiffness(cp, 208, 1 / 1.6e-4) == pytest.approx(5e5, rel=1e-12)
    assert cp.omega_dt == pytest.approx(0.5)
    assert cp.damping == pytest.approx(2 * cp.stiffness**0.5)
    assert 0.9 <= cp.impedance <= 0.9999
    soft = contact_params(1.0, 208, 1 / 1.6e-4, 0.5, 1 / 600)  # very soft: impedance capped at 0.9
    assert soft.impedance == pytest.approx(0.9) and soft.omega_dt < 0.5
    with pytest.raises(ParcelfitError):
        contact_params(-1, 208, 1, 1, 0.001)


def test_contact_dynamics_do_not_follow_the_time_step():
    """A finer step resolves the same contact (same solref/solimp, same static stiffness); a
    step too coarse for the contact's frequency softens it to omega * dt = 0.5."""
    at = {dt: contact_params(5e5, 208, 1 / 1.6e-4, 1.0, dt) for dt in (1 / 600, 1 / 1200, 1 / 2400)}
    assert at[1 / 1200] == dataclasses.replace(at[1 / 600], omega_dt=at[1 / 1200].omega_dt)
    assert at[1 / 2400].stiffness == at[1 / 600].stiffness == pytest.approx(300.0**2)
    assert at[1 / 2400].omega_dt == pytest.approx(0.125)
    coarse = contact_params(5e5, 208, 1 / 1.6e-4, 1.0, 1 / 300)
    assert coarse.omega_dt == pytest.approx(0.5) and coarse.stiffness == pytest.approx(150.0**2)
    for cp in (*at.values(), coarse):
        assert realised_stiffness(cp, 208, 1 / 1.6e-4) == pytest.approx(5e5, rel=1e-12)
    faster = contact_params(5e5, 208, 1 / 1.6e-4, 1.0, 1 / 2400, frequency=1200.0)
    assert faster.omega_dt == pytest.approx(0.5)


def test_contact_frequency_can_follow_the_stiffness():
    """With contact_frequency_stiffness K_ref a contact of stiffness K vibrates at
    contact_frequency * sqrt(K / K_ref), as a body on a spring does; the static stiffness stays
    K, the default keeps one frequency for every stiffness, and the scene's metal contact carries
    it (k_MePa 100 against 400 N/mm: half the frequency)."""
    from parcelfit.sim.mujoco.options import SceneOptions
    from parcelfit.sim.mujoco.scene import build_scene

    plain, scaled = SceneOptions(), SceneOptions(contact_frequency_stiffness=4e5)
    assert plain.frequency_for(1e5) == plain.frequency_for(1e6) == 300.0
    assert scaled.frequency_for(4e5) == pytest.approx(300.0)
    assert scaled.frequency_for(1e5) == pytest.approx(150.0)
    for k in (1e5, 1e6):
        cp = contact_params(k, 50, 1 / 1e-4, 1.0, 1 / 2400, frequency=scaled.frequency_for(k))
        assert cp.stiffness**0.5 == pytest.approx(scaled.frequency_for(k))
        assert realised_stiffness(cp, 50, 1 / 1e-4) == pytest.approx(k, rel=1e-12)
    with pytest.raises(ParcelfitError, match="contact_frequency_stiffness must be positive"):
        SceneOptions(contact_frequency_stiffness=0.0)

    rig, cons = load_rig("E3"), load_consignment("KPBW")

    def metal_solref(k_mepa: float) -> float:
        params = resolve(cons.content_kind, si_values={"k_MePa": k_mepa})
        xml = build_scene(rig, cons, params, 1, scaled).xml
        solrefs = {
            float(line.split('solref="')[1].split()[0])
            for line in xml.splitlines()
            if 'solref="' in line and 'name="guide' in line
        }
        assert len(solrefs) == 1, solrefs
        return -solrefs.pop()

    assert metal_solref(1e5) == pytest.approx(metal_solref(4e5) / 4, rel=1e-6)


@pytest.mark.mujoco
def test_mujoco_warnings_go_to_logging_not_into_a_log_file(tmp_path, monkeypatch, caplog):
    import mujoco
    import numpy as np

    import parcelfit.sim.mujoco  # noqa: F401  (installs the warning handler)

    monkeypatch.chdir(tmp_path)
    xml = "<mujoco><worldbody><body><freejoint/><geom size='.1'/></body></worldbody></mujoco>"
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    data.qvel[:] = np.nan
    with caplog.at_level("WARNING", logger="parcelfit.sim.mujoco"):
        mujoco.mj_step(model, data)
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
    assert "MuJoCo: Nan, Inf or huge value in QVEL at DOF 0" in caplog.text


def test_make_simulator_builds_what_the_configuration_says(tmp_path):
    from pathlib import Path

    import yaml

    import parcelfit.sim.mujoco
    from parcelfit.sim.factory import (
        SimulatorConfig,
        SimulatorSection,
        content_kind,
        make_simulator,
    )
    from parcelfit.sim.mujoco import MujocoSimulator

    doc = load_yaml(Path(parcelfit.sim.mujoco.__file__).parent / "rigs" / "E3.yaml")
    rig_file = tmp_path / "rigs" / "mine.yaml"  # a user's rig, known to no one else
    rig_file.parent.mkdir()
    rig_file.write_text(yaml.safe_dump({**doc, "name": "mine"}))
    section = SimulatorSection(
        backend="mujoco", rig="rigs/mine.yaml", consignment="PB", timestep=0.002, wall_limit=30
    )
    config = section.to_config(tmp_path)
    assert dict(config) == {
        "backend": "mujoco",
        "rig": str(rig_file.resolve()),  # a file's path is made absolute against its folder
        "consignment": "PB",
        "timestep": 0.002,
        "wall_limit": 30,
    }
    assert content_kind(config) == "soft"
    sim = make_simulator(config)
    assert isinstance(sim, MujocoSimulator)
    assert (sim.options.scene.timestep, sim.options.scene.spacing) == (0.002, None)
    # no spacing given: each type's own mesh (KP's 22.5 mm), else 30 mm; a soft content's film
    scene = sim.options.scene
    assert [scene.spacing_of(load_consignment(n)) for n in ("KP", "KPBW", "PB")] == [
        0.0225,
        0.03,
        scene.soft_shell_spacing,
    ]
    assert dataclasses.replace(scene, spacing=0.05).spacing_of(load_consignment("KP")) == 0.05
    assert sim.options.wall_limit == 30 and sim.rig("mine").name == "mine"
    recorder = sim.with_options(record_vertices=True)
    assert recorder.options == dataclasses.replace(sim.options, record_vertices=True)
    assert recorder.rig("mine") is sim.rig("mine") and not sim.options.record_vertices
    assert content_kind(SimulatorConfig("python", factory="tests.fake_sim:make")) == "rigid"
    with pytest.raises(ParcelfitError, match="the external backend needs 'external'"):
        SimulatorConfig("external")


def test_membrane_cap_keeps_the_bending_stiffness_and_caps_the_stretch():
    """The equivalent plate has the same D = E h^3 / 12 (1 - nu^2) and E h at the cap; below the
    cap, and without one, the shell's scene is unchanged (default runs stay as they were)."""
    import re

    from parcelfit.sim.mujoco.options import SceneOptions
    from parcelfit.sim.mujoco.scene import build_scene, equivalent_plate

    young, h = equivalent_plate(1e9, 5e-4, 3.125e4)
    assert young * h == pytest.approx(3.125e4, rel=1e-12)
    assert young * h**3 == pytest.approx(1e9 * 5e-4**3, rel=1e-12)
    assert (h, young) == pytest.approx((2e-3, 1.5625e7), rel=1e-12)
    assert equivalent_plate(1e8, 1e-4, 3.125e4) == (1e8, 1e-4)  # E h = 1e4 N/m: below the cap
    assert equivalent_plate(1e9, 5e-4, None) == (1e9, 5e-4)

    rig, cons = load_rig("E3"), load_consignment("KPBW")
    params = resolve(cons.content_kind, si_values={})

    def elasticity(options: SceneOptions) -> tuple[float, float, str]:
        xml = build_scene(rig, cons, params, 1, options).xml
        m = re.search(
            r'<elasticity young="([^"]+)" poisson="[^"]+" thickness="([^"]+)" '
            r'damping="([^"]+)"',
            xml,
        )
        assert m is not None
        return float(m[1]), float(m[2]), m[3]

    plain, capped = elasticity(SceneOptions()), elasticity(SceneOptions(membrane_cap=3.125e4))
    assert plain[:2] == (1e9, 5e-4)
    assert capped[:2] == pytest.approx((1.5625e7, 2e-3), rel=1e-9)
    assert capped[2] == plain[2]  # same bending stiffness and mass: the same damping
    assert elasticity(SceneOptions(membrane_cap=1e7)) == plain  # E h = 5e5 N/m below it
    with pytest.raises(ParcelfitError, match="membrane_cap must be positive"):
        SceneOptions(membrane_cap=0.0)


def test_membrane_cap_from_a_study_files_simulator_section(tmp_path):
    from parcelfit.sim.factory import SimulatorSection, make_simulator

    section = SimulatorSection(backend="mujoco", rig="E3", consignment="KPBW", membrane_cap=3e4)
    sim = make_simulator(section.to_config(tmp_path))
    assert sim.options.scene.membrane_cap == 3e4  # type: ignore[attr-defined]
    assert (
        make_simulator(  # not given: none
            SimulatorSection(backend="mujoco", rig="E3", consignment="KPBW").to_config(tmp_path)
        ).options.scene.membrane_cap
        is None
    )  # type: ignore[attr-defined]


def test_film_spacing_from_a_study_files_simulator_section_meshes_a_soft_contents_film(tmp_path):
    from parcelfit.runs import TestCase
    from parcelfit.sim.factory import SimulatorSection, make_simulator

    def film_vertices(**given: float) -> tuple[float, int]:
        section = SimulatorSection(backend="mujoco", rig="E3", consignment="PB", **given)
        sim = make_simulator(section.to_config(tmp_path))
        scene = sim.options.scene  # type: ignore[attr-defined]
        xml = sim.scene({}, TestCase("E3", "PB", 1)).xml  # type: ignore[attr-defined]
        shell = xml[xml.index('<flexcomp name="packaging"') :]
        points = shell[shell.index('point="') + 7 :]
        return scene.soft_shell_spacing, len(points[: points.index('"')].split()) // 3

    default_spacing, default_count = film_vertices()
    assert default_spacing == 0.05 and default_count == 98  # pillow_shell at 50 mm
    fine_spacing, fine_count = film_vertices(film_spacing=0.03)
    assert fine_spacing == 0.03 and fine_count == 218
    with pytest.raises(ParcelfitError, match=r"must lie in \[5, 200\] mm, got 1 mm"):
        film_vertices(film_spacing=0.001)


def test_bulge_lowers_a_flat_patch_under_the_content_and_leaves_other_shells_alone():
    """The bulging bottom: a flat patch of f times the outer size, d below the content's face,
    rising linearly to the content's edges; the belt-contact face is that patch. Without a bulge
    the mesh is the plain pillow (grid lines on the content's edges, bottom flat under it)."""
    import numpy as np

    from parcelfit.sim.mujoco.shell import pillow_shell

    outer, content, h, d, f = (0.2, 0.15), (0.165, 0.125), 0.0115, 0.004, 0.3
    flat = pillow_shell(outer, content, h, 0.03)
    bulged = pillow_shell(outer, content, h, 0.03, (d, f))
    assert flat.bulge_depth == 0.0 and bulged.bulge_depth == d
    face = flat.points[flat.bottom_face]
    assert np.allclose(face[:, 2], -h) and np.ptp(face[:, 0]) == pytest.approx(content[0])
    patch = bulged.points[bulged.bottom_face]
    assert np.allclose(patch[:, 2], -h - d)
    assert np.ptp(patch[:, 0]) == pytest.approx(f * outer[0])
    assert np.ptp(patch[:, 1]) == pytest.approx(f * outer[1])
    # the bottom between the patch and the content's edge rises linearly to -h at the edge
    pts = bulged.points
    bottom = pts[pts[:, 2] < -h + 1e-12]
    x_edge = bottom[
        np.isclose(np.abs(bottom[:, 0]), content[0] / 2) & (np.abs(bottom[:, 1]) < 0.01)
    ]
    assert x_edge.size and np.allclose(x_edge[:, 2], -h)
    # top sheet and seam untouched
    assert np.allclose(pts[bulged.top][:, 2], h) and np.allclose(pts[bulged.seam][:, 2], 0)
    assert bulged.face_contacts < flat.face_contacts
    with pytest.raises(ParcelfitError, match=r"patch .* smaller than the content"):
        pillow_shell(outer, content, h, 0.03, (d, 0.9))


def test_consignment_bulge_is_checked_and_moves_the_parcel_up_by_its_depth():
    good = {
        "name": "X",
        "mass": 0.1,
        "outer": [0.2, 0.15, 0.02],
        "content": {"kind": "rigid", "size": [0.165, 0.125, 0.02]},
        "bulge": {"depth": 0.004, "footprint": 0.3},
    }
    assert parse_consignment(good, "c.yaml").bulge == (0.004, 0.3)
    assert parse_consignment({**good, "bulge": None}, "c.yaml").bulge is None
    with pytest.raises(ParcelfitError, match=r"c\.yaml: bulge\.footprint: .*not smaller"):
        parse_consignment({**good, "bulge": {"depth": 0.004, "footprint": 0.9}}, "c.yaml")
    with pytest.raises(ParcelfitError, match=r"bulge\.depth"):
        parse_consignment({**good, "bulge": {"depth": 0.2, "footprint": 0.3}}, "c.yaml")
    soft = {**good, "content": {"kind": "soft", "size": [0.165, 0.125, 0.02]}}
    with pytest.raises(ParcelfitError, match="a bulge needs a rigid content"):
        parse_consignment(soft, "c.yaml")

    from parcelfit.sim.mujoco.options import SceneOptions
    from parcelfit.sim.mujoco.scene import build_scene

    rig = load_rig("E3")
    flat = dataclasses.replace(load_consignment("BW"), bulge=None)
    bulged = dataclasses.replace(flat, bulge=(0.004, 0.3))
    params = resolve(flat.content_kind, si_values={})

    def height(c: object) -> float:
        import re

        full = SceneOptions(shell_dof="full")  # the flexcomp itself carries the position
        xml = build_scene(rig, c, params, 1, full).xml  # type: ignore[arg-type]
        m = re.search(r'<flexcomp name="packaging"[^>]* pos="[^ ]+ [^ ]+ ([^"]+)"', xml)
        assert m is not None
        return float(m[1])

    assert height(bulged) - height(flat) == pytest.approx(0.004)
    # a consignment changed in code, past the file's check, is refused by the scene
    pb = dataclasses.replace(load_consignment("PB"), bulge=(0.004, 0.5))
    with pytest.raises(ParcelfitError, match="a bulge needs a rigid content"):
        build_scene(rig, pb, resolve(pb.content_kind, si_values={}), 1)


def test_impratio_reaches_the_model_and_is_checked():
    from parcelfit.sim.mujoco.options import SceneOptions
    from parcelfit.sim.mujoco.scene import build_scene

    rig, cons = load_rig("E3"), load_consignment("KPBW")
    params = resolve(cons.content_kind, si_values={})
    # the penalty law's default stiffens MuJoCo's friction rows (scene.py, PENALTY_IMPRATIO)
    assert 'impratio="10000"' in build_scene(rig, cons, params, 1, SceneOptions()).xml
    impedance = SceneOptions(contact_law="impedance")
    assert 'impratio="1"' in build_scene(rig, cons, params, 1, impedance).xml
    assert 'impratio="10"' in build_scene(rig, cons, params, 1, SceneOptions(impratio=10)).xml
    with pytest.raises(ParcelfitError, match="impratio must be at least 1"):
        SceneOptions(impratio=0.5)


def _scene_at_rest(name, options):
    from parcelfit.sim.mujoco.scene import build_scene

    cons = load_consignment(name)
    return build_scene(load_rig("E3"), cons, resolve(cons.content_kind, si_values={}), 1, options)


def _deepest_shell_content_contact(scene) -> float:
    """The most negative distance [m] MuJoCo reports between the packaging and its content in
    the scene's start pose (0 when they do not touch)."""
    import mujoco

    model = scene.model()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    packaging = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
    content_flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "content")
    content_geom = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "content")
    overlaps = [
        float(data.contact.dist[i])
        for i in range(data.ncon)
        if (content_geom >= 0 and content_geom in data.contact.geom[i])
        or (content_flex >= 0 and set(data.contact.flex[i]) == {packaging, content_flex})
    ]
    return min(overlaps, default=0.0)


def test_ccd_tolerance_is_tight_around_a_soft_content_and_can_be_set():
    """1e-8 m around the polybag's soft content, MuJoCo's default around a rigid one. At
    MuJoCo's own 1e-6 a vertex of the 50 mm film lying right above one of the 100 mm content's
    is reported 0.2 mm deep in it at rest, where the two just touch (docs/research/pb-speed.md)."""
    from parcelfit.sim.mujoco.options import SceneOptions

    def option(name, **given):
        return _scene_at_rest(name, SceneOptions(**given)).model().opt.ccd_tolerance

    assert _deepest_shell_content_contact(_scene_at_rest("PB", SceneOptions())) > -1e-5
    loose = _deepest_shell_content_contact(_scene_at_rest("PB", SceneOptions(ccd_tolerance=1e-6)))
    assert loose == pytest.approx(-1.96e-4, abs=1e-5)
    assert option("PB") == pytest.approx(1e-8)
    assert option("KPBW") == pytest.approx(1e-6)  # MuJoCo's own
    assert option("PB", ccd_tolerance=1e-6) == pytest.approx(1e-6)
    assert option("KPBW", ccd_tolerance=1e-9) == pytest.approx(1e-9)
    with pytest.raises(ParcelfitError, match="ccd_tolerance must be positive"):
        SceneOptions(ccd_tolerance=0.0)


@pytest.mark.parametrize("name", ["BW", "KPBW", "KP", "PB"])
@pytest.mark.parametrize("dof", ["auto", "full"])
def test_the_shell_touches_its_content_nowhere_at_rest(name, dof):
    """At the start the shell presses on its content nowhere: no packaging-content contact
    penetrates (the polybag's sheets lie at the contact distance from its content's vertices,
    so they touch without overlap), and the flat bands widen only where a short rim's taper
    would pass the content's edge closer than the contact distance (KP's 5 mm rim around 3 cm,
    the polybag's 12.5 mm around 1.8 cm). A shell that touches pushes on its content from the
    first step and clamps it."""
    import numpy as np

    from parcelfit.sim.mujoco.options import SceneOptions

    scene = _scene_at_rest(name, SceneOptions(shell_dof=dof))
    assert _deepest_shell_content_contact(scene) > -1e-5  # [m]; unwidened: KP 0.57, PB 0.35 mm
    # the flat top sheet spans the content's footprint, widened on KP's and PB's axes only
    top = scene.shell.points[scene.shell.top]
    widened = {"BW": (0, 0), "KPBW": (0, 0), "KP": (2.39e-3, 1.55e-3), "PB": (1.13e-3, 1.13e-3)}
    for axis in (0, 1):
        assert np.ptp(top[:, axis]) == pytest.approx(
            load_consignment(name).content[axis] + widened[name][axis], abs=2e-5
        )


def test_the_edge_widening_clears_the_content_by_the_sheets_clearance():
    """d(g) of the shell module's docstring: 0 where the taper already lies beyond the contact
    distance; otherwise the g at which the taper's line lies exactly the clearance from the
    content's edge (checked against the point-line distance), and a rim shorter than the
    clearance is refused."""
    import math

    from parcelfit.sim.mujoco.shell import edge_widening

    assert edge_widening(0.0175, 0.0115, 0.0015, 0.001) == 0.0  # BW: 1.25 mm > 1 mm
    rim, H, s = 0.005, 0.0165, 0.0015  # KP along its length
    g = edge_widening(rim, H, s, 0.001)
    assert 0 < g < rim
    # the taper from (g, H) to (rim, 0) against the content's edge at (0, H - s)
    (ax, ay), (bx, by), (px, py) = (g, H), (rim, 0.0), (0.0, H - s)
    distance = abs((bx - ax) * (ay - py) - (ax - px) * (by - ay)) / math.hypot(bx - ax, by - ay)
    assert distance == pytest.approx(s, rel=1e-9)
    with pytest.raises(ParcelfitError, match="rim"):
        edge_widening(0.001, H, s, 0.001)


def test_an_interpolated_shells_nodes_span_the_parcels_own_box():
    """MuJoCo lays an interpolated shell's nodes on a box aligned with the flexcomp's parent
    body; the scene puts the shell in a static frame turned like the parcel (E3 starts at 30
    degrees), so the nodes span the parcel's length and width, not a world-aligned box."""
    import math

    import mujoco
    import numpy as np

    from parcelfit.sim.mujoco.options import SceneOptions
    from parcelfit.sim.mujoco.scene import build_scene

    rig, cons = load_rig("E3"), load_consignment("KPBW")
    params = resolve(cons.content_kind, si_values={})
    scene = build_scene(rig, cons, params, 1, SceneOptions(shell_dof="quadratic"))
    model = scene.model()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    adr, num = model.flex_nodeadr[0], model.flex_nodenum[0]
    assert num == 27
    nodes = np.array([data.xpos[b][:2] for b in model.flex_nodebodyid[adr : adr + num]])
    h = math.radians(rig.start.heading)
    along = nodes @ np.array([math.cos(h), math.sin(h)])
    across = nodes @ np.array([-math.sin(h), math.cos(h)])
    assert np.ptp(along) == pytest.approx(cons.outer[0], abs=1e-6)
    assert np.ptp(across) == pytest.approx(cons.outer[1], abs=1e-6)
    full = SceneOptions(shell_dof="full")
    assert "packaging_frame" not in build_scene(rig, cons, params, 1, full).xml


def test_the_default_step_follows_the_shell_and_a_given_step_wins():
    """1/2400 s around a rigid content (interpolated shell), 1/1200 s around a soft one (full
    shell) or for a full shell asked for explicitly; a given ``timestep`` overrides both."""
    import re

    from parcelfit.sim.mujoco.options import SceneOptions
    from parcelfit.sim.mujoco.scene import build_scene

    def step(cons_name: str, options: SceneOptions) -> float:
        cons = load_consignment(cons_name)
        # E3 does not refine the default step (E1 does: the next tests)
        xml = build_scene(load_rig("E3"), cons, resolve(cons.content_kind), 1, options).xml
        m = re.search(r'<option timestep="([^"]+)"', xml)
        assert m is not None
        return float(m[1])

    assert step("KPBW", SceneOptions()) == pytest.approx(1 / 2400)
    assert step("PB", SceneOptions()) == pytest.approx(1 / 1200)
    assert step("KPBW", SceneOptions(shell_dof="full")) == pytest.approx(1 / 1200)
    assert step("PB", SceneOptions(timestep=1 / 600)) == pytest.approx(1 / 600)
    assert step("PB", SceneOptions(friction="geom", belt_friction="coulomb")) == pytest.approx(
        1 / 2400
    )
    assert SceneOptions().step_for(soft=False) == pytest.approx(1 / 2400)
    with pytest.raises(ParcelfitError, match="timestep must lie in"):
        SceneOptions(timestep=0.1)


def test_scene_options_read_from_key_value_texts():
    """``KEY=VALUE`` texts (the scripts' ``--scene``) become `SceneOptions` arguments: numbers
    and fractions as floats, other values as text; a text without ``=`` is refused."""
    from parcelfit.sim.mujoco.options import SceneOptions, parse_scene_options

    given = parse_scene_options(["timestep=1/2400", "shell_dof=full", " impratio = 10 "])
    assert given == {"timestep": 1 / 2400, "shell_dof": "full", "impratio": 10.0}
    assert SceneOptions(**given).step_for(soft=False) == 1 / 2400  # type: ignore[arg-type]
    with pytest.raises(ParcelfitError, match="not KEY=VALUE"):
        parse_scene_options(["timestep"])
    offset = parse_scene_options(["start_offset=-0.0125, 0.02165,1/2"])
    assert offset == {"start_offset": (-0.0125, 0.02165, 0.5)}
    assert SceneOptions(**offset).start_offset == (-0.0125, 0.02165, 0.5)  # type: ignore[arg-type]
    assert parse_scene_options(["shell_dof=a,b"]) == {"shell_dof": "a,b"}


def test_scene_options_from_texts_refuse_an_unknown_key_and_a_bad_value():
    from parcelfit.sim.mujoco.options import SceneOptions, scene_options

    opt = scene_options(["spacing=0.06", "timestep=1/4800"])
    assert opt == SceneOptions(spacing=0.06, timestep=1 / 4800)
    assert scene_options(["shell_cells=4,3,1"]).shell_cells == (4, 3, 1)
    with pytest.raises(ParcelfitError, match="shell cells must be three whole numbers"):
        scene_options(["shell_cells=4,3"])
    assert scene_options([]) == SceneOptions()
    with pytest.raises(ParcelfitError, match=r"unknown scene option\(s\) colour, sapcing"):
        scene_options(["sapcing=0.06", "colour=red"])
    with pytest.raises(ParcelfitError, match="unknown shell_dof 'floppy'"):
        scene_options(["shell_dof=floppy"])


def test_belt_friction_from_a_study_files_simulator_section_and_a_twins_settings(tmp_path):
    from parcelfit.sim.factory import SimulatorSection, make_simulator
    from parcelfit.synth import TwinSettings, TwinSettingsSection

    section = SimulatorSection(
        backend="mujoco", rig="E3", consignment="KPBW", friction="geom", belt_friction="coulomb"
    )
    sim = make_simulator(section.to_config(tmp_path))
    assert sim.options.scene.belt_friction == "coulomb"  # type: ignore[attr-defined]
    assert sim.options.scene.friction == "geom"  # type: ignore[attr-defined]
    laws = SimulatorSection(
        backend="mujoco", rig="E3", consignment="KPBW", contact_law="impedance", friction="geom"
    )
    scene = make_simulator(laws.to_config(tmp_path)).options.scene  # type: ignore[attr-defined]
    assert (scene.contact_law, scene.friction) == ("impedance", "geom")
    mapped = SimulatorSection(
        backend="mujoco", rig="E3", consignment="KPBW", contact_mapping="solver"
    )
    scene = make_simulator(mapped.to_config(tmp_path)).options.scene  # type: ignore[attr-defined]
    assert scene.contact_mapping == "solver"
    with pytest.raises(Exception, match="unknown contact mapping 'area'"):
        SimulatorSection(backend="mujoco", rig="E3", consignment="KPBW", contact_mapping="area")
    with pytest.raises(Exception, match="contact_mapping"):
        make_simulator(
            SimulatorSection(
                backend="rigidbox", rig="E3", consignment="KPBW", contact_mapping="solver"
            ).to_config(tmp_path)
        )
    with pytest.raises(Exception, match="friction=geom"):
        make_simulator(
            SimulatorSection(
                backend="mujoco", rig="E3", consignment="KPBW", belt_friction="coulomb"
            ).to_config(tmp_path)
        )
    default = SimulatorSection(backend="mujoco", rig="E3", consignment="KPBW")
    assert make_simulator(default.to_config(tmp_path)).options.scene.belt_friction == "mujoco"  # type: ignore[attr-defined]
    assert TwinSettings().real_belt_friction == "mujoco"
    assert TwinSettingsSection(real_belt_friction="coulomb").real_belt_friction == "coulomb"
    with pytest.raises(Exception, match="unknown belt friction law 'dry'"):
        TwinSettingsSection(real_belt_friction="dry")


def test_roller_surface_and_shell_diagonals_from_a_study_files_simulator_section(tmp_path):
    """``roller_surface`` and ``shell_diagonals`` in a study's simulator section reach the
    scene (the flow splitter's rollers turn: their geoms carry a spin; the shell's cells split
    the other way: another mesh), and leaving them out keeps the defaults."""
    from parcelfit.runs import TestCase
    from parcelfit.sim.factory import SimulatorSection, make_simulator

    def sim(**given):
        section = SimulatorSection(backend="mujoco", rig="E2a", consignment="KPBW", **given)
        return make_simulator(section.to_config(tmp_path))

    default, turning = sim(), sim(roller_surface="turning", shell_diagonals="alternating")
    assert default.options.scene.roller_surface == "linear"  # type: ignore[attr-defined]
    assert default.options.scene.shell_diagonals == "radiating"  # type: ignore[attr-defined]
    assert turning.options.scene.roller_surface == "turning"  # type: ignore[attr-defined]
    assert turning.options.scene.shell_diagonals == "alternating"  # type: ignore[attr-defined]
    case = TestCase("E2a", "KPBW", 1)
    a, b = default.scene({}, case), turning.scene({}, case)  # type: ignore[attr-defined]
    rollers = [g for g in b.driven if g.surface == "splitter"]
    assert len(rollers) == 56 and all(g.spin is not None for g in rollers)
    assert all(g.spin is None for g in a.driven if g.surface == "splitter")
    assert a.shell.triangles.tolist() != b.shell.triangles.tolist()


def test_the_shells_degrees_of_freedom_from_a_study_file_and_the_simulate_command(tmp_path):
    """``shell_dof`` in a study's simulator section (and `parcelfit simulate --shell-dof`)
    reaches the scene: the full shell gets one degree of freedom per vertex, the default stays
    ``auto`` (the consignment file's shell), and an unknown value is refused; ``shell_cells``
    (and ``--shell-cells``) likewise."""
    from typer.testing import CliRunner

    from parcelfit.cli import app
    from parcelfit.sim.factory import SimulatorConfig, SimulatorSection, make_simulator

    full = SimulatorSection(backend="mujoco", rig="E3", consignment="KPBW", shell_dof="full")
    sim = make_simulator(full.to_config(tmp_path))
    assert sim.options.scene.shell_dof == "full"  # type: ignore[attr-defined]
    assert sim.options.scene.shell_for(soft=False) == "full"  # type: ignore[attr-defined]
    default = SimulatorSection(backend="mujoco", rig="E3", consignment="KPBW")
    assert "shell_dof" not in dict(default.to_config(tmp_path))
    assert make_simulator(default.to_config(tmp_path)).options.scene.shell_dof == "auto"  # type: ignore[attr-defined]
    with pytest.raises(ParcelfitError, match="unknown shell_dof 'floppy'"):
        make_simulator(SimulatorConfig("mujoco", rig="E3", consignment="KPBW", shell_dof="floppy"))
    result = CliRunner().invoke(
        app, ["simulate", "--shell-dof", "floppy", "--out", str(tmp_path / "r.csv")]
    )
    assert result.exit_code != 0
    assert "unknown shell_dof 'floppy'" in result.output
    assert not (tmp_path / "r.csv").exists()
    # the shell's grid of cells: from the section to the scene, and refused when it is no grid
    cells = SimulatorSection(backend="mujoco", rig="E3", consignment="KPBW", shell_cells=[2, 3, 1])
    scene = make_simulator(cells.to_config(tmp_path)).options.scene  # type: ignore[attr-defined]
    assert scene.shell_cells == (2, 3, 1)
    for text, message in (("4,4,x", "is not three numbers"), ("4,0,1", "three whole numbers")):
        result = CliRunner().invoke(
            app, ["simulate", "--shell-cells", text, "--out", str(tmp_path / "r.csv")]
        )
        assert result.exit_code != 0
        assert message in result.output
        assert not (tmp_path / "r.csv").exists()


def test_the_static_friction_law_from_a_study_files_simulator_section(tmp_path):
    from parcelfit.sim.factory import SimulatorSection, make_simulator

    section = SimulatorSection(
        backend="mujoco", rig="E3", consignment="KPBW", stick_speed=0.1, slip_speed=1.0
    )
    scene = make_simulator(section.to_config(tmp_path)).options.scene  # type: ignore[attr-defined]
    assert (scene.stick_speed, scene.slip_speed) == (0.1, 1.0)
    default = SimulatorSection(backend="mujoco", rig="E3", consignment="KPBW")
    scene = make_simulator(default.to_config(tmp_path)).options.scene  # type: ignore[attr-defined]
    assert (scene.stick_speed, scene.slip_speed) == (0.005, None)
    with pytest.raises(Exception, match=r"slip_speed \(0\.004 m/s\) must exceed stick_speed"):
        SimulatorSection(backend="mujoco", rig="E3", consignment="KPBW", slip_speed=0.004)


def test_a_rig_may_have_its_own_time_step(tmp_path):
    """``rig_timesteps`` (study file: ``simulator.rig_timesteps``) sets the step of runs on the
    rigs it names and leaves the others at theirs; the run really steps at it."""
    from parcelfit.runs import TestCase
    from parcelfit.sim.factory import SimulatorSection, make_simulator
    from parcelfit.sim.mujoco import SceneOptions, load_rig

    section = SimulatorSection(
        backend="mujoco", rig="E3", consignment="KPBW", rig_timesteps={"E1": 1 / 4800}
    )
    sim = make_simulator(section.to_config(tmp_path))
    scene = sim.options.scene  # type: ignore[attr-defined]
    assert scene.step_for(soft=False, rig=load_rig("E1")) == 1 / 4800
    assert scene.step_for(soft=False, rig=load_rig("E3")) == 1 / 2400
    short = sim.with_options(duration=0.05)  # type: ignore[attr-defined]
    for rig, step in (("E1", 1 / 4800), ("E3", 1 / 2400)):
        d = short.run({}, TestCase(rig, "KPBW", 1)).diagnostics
        assert d["simulated_time"] / d["steps"] == pytest.approx(step, rel=1e-9)
    with pytest.raises(ParcelfitError, match="time step for rig E1"):
        SceneOptions(rig_timesteps={"E1": 1.0})


def test_a_rig_file_refines_the_default_step_on_its_own_runs(tmp_path):
    """E1's rig file halves the default step (``step_refinement: 2``): 1/4800 s around rigid
    contents, 1/2400 s around the soft one; E3 keeps the defaults; a study's ``rig_timesteps``
    or an explicit ``timestep`` wins; the run really steps at it."""
    from parcelfit.runs import TestCase
    from parcelfit.sim.mujoco import MujocoSimulator, SceneOptions, SimOptions
    from parcelfit.sim.mujoco.scene import build_scene

    e1, e3 = load_rig("E1"), load_rig("E3")
    assert (e1.step_refinement, e3.step_refinement) == (2, 1)
    sim = MujocoSimulator()
    assert sim.options.scene.step_for(soft=False, rig=e1) == pytest.approx(1 / 4800)
    assert sim.options.scene.step_for(soft=True, rig=e1) == pytest.approx(1 / 2400)
    assert sim.options.scene.step_for(soft=False, rig=e3) == pytest.approx(1 / 2400)
    assert sim.options.scene.step_for(soft=True, rig=e3) == pytest.approx(1 / 1200)
    own = MujocoSimulator(SimOptions(scene=SceneOptions(rig_timesteps={"E1": 1 / 2400})))
    assert own.options.scene.step_for(soft=False, rig=e1) == pytest.approx(1 / 2400)
    given = MujocoSimulator(SimOptions(scene=SceneOptions(timestep=1 / 1000)))
    assert given.options.scene.step_for(soft=False, rig=e1) == pytest.approx(1 / 1000)
    d = sim.with_options(duration=0.02).run({}, TestCase("E1", "KPBW", 1)).diagnostics
    assert d["simulated_time"] / d["steps"] == pytest.approx(1 / 4800, rel=1e-9)
    # a scene built directly for the rig steps at it too
    cons = load_consignment("KPBW")
    xml = build_scene(e1, cons, resolve("rigid"), 1, SceneOptions()).xml
    assert f'timestep="{1 / 4800:.9g}"' in xml


@pytest.mark.parametrize("spacing", [0.02, 0.03, 0.04, 0.05])
def test_radiating_diagonals_make_the_shell_mirror_symmetric_at_every_spacing(spacing):
    """The default triangulation is the same under x -> -x and y -> -y (but in a row of cells
    that straddles an axis, where no diagonal is), and each corner of the seam is the tip of two
    triangles per sheet, whatever the cell counts' parity; the old alternating one is not
    symmetric at a 40 mm film (the polybag's default until 2026-11-29), where two corners are the tip of only one
    triangle per sheet (shell.py, "Diagonals")."""
    import numpy as np

    from parcelfit.sim.mujoco.options import SceneOptions
    from parcelfit.sim.mujoco.shell import pillow_shell

    def shell(diagonals):
        return pillow_shell(
            (0.315, 0.225),
            (0.29, 0.20),
            0.0105,
            spacing,
            diagonals=diagonals,
            content_half_height=0.009,
            contact=0.0015,
        )

    def triangles_as_points(mesh, flip):  # those of cells that do not straddle an axis
        pts = mesh.points * np.array(flip)
        cells = [t for t in mesh.triangles if np.ptp(np.sign(np.round(pts[t, :2], 9)), 0).max() < 2]
        return {tuple(sorted(tuple(np.round(pts[k], 9) + 0.0) for k in t)) for t in cells}

    def corner_tips(mesh):
        corners = [
            k for k in mesh.seam if np.allclose(np.abs(mesh.points[k, :2]), (0.1575, 0.1125))
        ]
        assert len(corners) == 4
        return [int((mesh.triangles == k).sum()) for k in corners]

    radiating = shell("radiating")
    plain = triangles_as_points(radiating, (1, 1, 1))
    assert triangles_as_points(radiating, (-1, 1, 1)) == plain
    assert triangles_as_points(radiating, (1, -1, 1)) == plain
    assert corner_tips(radiating) == [4, 4, 4, 4]  # two triangles in each sheet
    alternating = shell("alternating")
    assert len(alternating.triangles) == len(radiating.triangles)
    if spacing == 0.04:
        assert sorted(corner_tips(alternating)) == [2, 2, 4, 4]
        assert triangles_as_points(alternating, (-1, 1, 1)) != triangles_as_points(
            alternating, (1, 1, 1)
        )
    with pytest.raises(ParcelfitError, match="unknown shell diagonals 'crossed'"):
        shell("crossed")
    with pytest.raises(ParcelfitError, match="unknown shell_diagonals 'crossed'"):
        SceneOptions(shell_diagonals="crossed")


def test_a_study_may_fit_cases_on_several_rig_files_of_its_own(tmp_path):
    """``simulator.rigs``: bench tests beside the bundled rigs and the simulator's own rig, as
    `parcelfit design` may recommend two; their rigs are known to the study's simulator and to a
    design on one of them, and a name given twice is refused naming the entry."""
    import shutil
    from pathlib import Path

    import yaml

    from parcelfit.sim.factory import make_simulator
    from parcelfit.study.plausible import check_design, design_simulator
    from parcelfit.study.studyfile import load_study

    bench = Path(__file__).resolve().parent.parent / "examples" / "bench"
    (tmp_path / "rigs").mkdir()
    for name in ("B1", "B2"):
        shutil.copy(bench / f"{name}.yaml", tmp_path / "rigs" / f"{name}.yaml")
    doc = {
        "name": "bench",
        "simulator": {
            "backend": "mujoco",
            "rig": "E3",
            "consignment": "KPBW",
            "rigs": ["rigs/B1.yaml", "rigs/B2.yaml"],
        },
        "parameters": {"mu_d_BePa": [0.3, 0.6]},
        "cases": [
            {"dataset": "data", "speed_setting": 1},
            {"rig": "B1", "speed_setting": 1},
            {"rig": "B2", "speed_setting": 2},
        ],
    }
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    study = load_study(path)
    assert [c.case.label for c in study.cases] == ["E3/KPBW/1", "B1/KPBW/1", "B2/KPBW/2"]
    assert study.simulator["rigs"] == tuple(
        str((tmp_path / "rigs" / f"{n}.yaml").resolve()) for n in ("B1", "B2")
    )
    sim = make_simulator(study.simulator)
    assert [sim.rig(n).name for n in ("E3", "B1", "B2")] == ["E3", "B1", "B2"]
    assert sim.rig("B2").speeds[2] == {"belt": 2.0}
    # a design on one of the study's own rig files runs with the other still known
    on_b1 = design_simulator(study, check_design(str(tmp_path / "rigs" / "B1.yaml"), "KPBW", 1))
    assert on_b1.rig("B1").name == "B1" and on_b1.rig("B2").name == "B2"
    # the same rig twice, or a file that names a bundled rig, is refused at load
    doc["simulator"]["rigs"] = ["rigs/B1.yaml", "rigs/B1.yaml"]
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.raises(ParcelfitError, match="a rig named B1 is known already") as err:
        load_study(path)
    assert err.value.where == "simulator.rigs[1]"
    e3 = load_yaml(Path(parcelfit_rigs_folder(), "E3.yaml"))
    (tmp_path / "rigs" / "E3.yaml").write_text(yaml.safe_dump(e3))
    doc["simulator"]["rigs"] = ["rigs/E3.yaml"]
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.raises(ParcelfitError, match="a rig named E3 is known already"):
        load_study(path)


def test_a_rig_or_consignment_file_whose_name_is_not_its_stem_is_refused_by_a_study(tmp_path):
    """A study names its simulator's rig and consignment by the file's stem and the simulator by
    the file's ``name:``: a copy of B1 saved as B9.yaml, still saying ``name: B1``, would let a
    case name B9 that the simulator cannot find, so the study refuses it on load."""
    import shutil
    from pathlib import Path

    import yaml

    from parcelfit.study.studyfile import load_study

    bench = Path(__file__).resolve().parent.parent / "examples" / "bench"
    shutil.copy(bench / "B1.yaml", tmp_path / "B9.yaml")
    doc = {
        "name": "renamed",
        "simulator": {"backend": "mujoco", "rig": "B9.yaml", "consignment": "KPBW"},
        "parameters": {"mu_d_BePa": [0.3, 0.6]},
        "cases": [{"dataset": "data", "speed_setting": 1}],
    }
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.raises(ParcelfitError, match=r"the rig file B9\.yaml says name: B1") as err:
        load_study(path)
    assert err.value.where == "simulator.rig"
    assert err.value.fix == (
        "make the rig file's name equal its file name without .yaml (B9), or rename the file "
        "to B1.yaml"
    )
    # the same among simulator.rigs, and for the consignment file
    doc["simulator"].update(rig="E3", rigs=["B9.yaml"])
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.raises(ParcelfitError, match=r"the rig file B9\.yaml says name: B1") as err:
        load_study(path)
    assert err.value.where == "simulator.rigs[0]"
    kpbw = Path(parcelfit_rigs_folder().parent, "consignments", "KPBW.yaml")
    shutil.copy(kpbw, tmp_path / "mailer.yaml")
    doc["simulator"] = {"backend": "mujoco", "rig": "E3", "consignment": "mailer.yaml"}
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.raises(ParcelfitError, match=r"the consignment file mailer\.yaml says name: KPBW"):
        load_study(path)
    # renamed inside as well, it loads
    text = (tmp_path / "mailer.yaml").read_text()
    (tmp_path / "mailer.yaml").write_text(text.replace("name: KPBW", "name: mailer", 1))
    assert load_study(path).cases[0].case.consignment == "mailer"


def test_rig_files_are_loaded_by_name_and_a_name_given_twice_is_refused(tmp_path):
    """`load_rig_files` (the simulator's rigs, `track-all --rig`): each file's rig by its name,
    after the rigs already known; the same name twice names the second file and the key."""
    import shutil
    from pathlib import Path

    from parcelfit.sim.mujoco import load_rig, load_rig_files

    bench = Path(__file__).resolve().parent.parent / "examples" / "bench"
    rigs = load_rig_files([bench / "B1.yaml", bench / "B2.yaml"], {"E3": load_rig("E3")})
    assert list(rigs) == ["E3", "B1", "B2"] and rigs["B2"].speeds[2] == {"belt": 2.0}
    shutil.copy(bench / "B1.yaml", tmp_path / "B1.yaml")
    with pytest.raises(ParcelfitError, match="two rigs are named B1") as err:
        load_rig_files([bench / "B1.yaml", tmp_path / "B1.yaml"], where="--rig")
    assert err.value.file == str(tmp_path / "B1.yaml") and err.value.where == "--rig"


def parcelfit_rigs_folder():
    """The folder of the bundled rig files."""
    from pathlib import Path

    import parcelfit.sim.mujoco

    return Path(parcelfit.sim.mujoco.__file__).parent / "rigs"


def test_with_bulge_gives_a_flat_or_bulged_bottom_and_refuses_a_negative_one():
    from parcelfit.errors import ParcelfitError
    from parcelfit.sim.mujoco.consignment import BULGE_DEPTH, with_bulge

    bw = load_consignment("BW")
    assert with_bulge(bw, None) is bw  # as its file says
    assert bw.bulge is not None and with_bulge(bw, 0).bulge is None  # 0: flat
    assert with_bulge(load_consignment("KPBW"), 0.55).bulge == (BULGE_DEPTH, 0.55)
    assert with_bulge(bw, 0.4, 0.002).bulge == (0.002, 0.4)
    for footprint, depth in ((-0.5, BULGE_DEPTH), (0.5, 0.0), (0.5, -0.001)):
        with pytest.raises(ParcelfitError, match="0 \\(a flat bottom\\) or positive"):
            with_bulge(bw, footprint, depth)
