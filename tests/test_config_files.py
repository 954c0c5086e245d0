"""The typed file models (study, screen, twin spec, tag map, rig, consignment): every refusal
names the file, the key and the fix; values are converted to SI once, on load."""

from types import MappingProxyType

import pytest
import yaml

from parcelfit import ParcelfitError
from parcelfit.runs import Barrier, Box
from parcelfit.sim.mujoco import load_consignment, load_rig
from parcelfit.sim.mujoco.consignment import Consignment
from parcelfit.sim.mujoco.rig import EndCondition, Rig, StartPose, Surface, Wall
from parcelfit.study.screening import load_screen
from parcelfit.study.studyfile import load_study
from parcelfit.synth import load_twin_spec
from parcelfit.tracking import load_tag_map

SIM = {"backend": "python", "factory": "tests.fake_sim:make"}
REF = {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1}


def _on_e3_kpbw(**reference: object) -> dict:
    """A study's or screen's keys that run the MuJoCo model of E3 with KP/BW, its reference
    case there (``reference`` keys added, e.g. speed_setting)."""
    return {
        "simulator": {"backend": "mujoco", "rig": "E3", "consignment": "KPBW"},
        "reference": {**REF, "rig": "E3", "consignment": "KPBW", **reference},
    }


STUDY = {"name": "s", "simulator": SIM, "parameters": {"mu_d_BePa": [0.3, 0.6]}, "reference": REF}
SCREEN = {
    "name": "s",
    "simulator": SIM,
    "reference": REF,
    "parameters": {"mu_d_BePa": [0.3, 0.58], "E_Pa": [200, 1600]},
}
TWIN = {"cases": ["E1/BW/1"], "truth": {"BW": {"mu_d_BePa": 0.5}}, "settings": {"runs": 2}}
TAGS = {
    "reference_tags": {0: {"x": 0.0, "y": 0.0, "size": 0.08}},
    "parcel_tags": {5: {"size": 0.06}},
    "camera": {"fx": 1000, "fy": 1000, "cx": 640, "cy": 360},
    "light_barriers": [{"id": "start", "from": [0.2, -0.5], "to": [0.2, 0.5]}],
}
RIG = {
    "name": "R",
    "speeds": {1: {"main": 1.5, "strip": 1.6}},
    "surfaces": [
        {
            "name": "main",
            "type": "belt",
            "material": "belt",
            "centre": [1, 0],
            "length": 3,
            "width": 0.8,
            "heading": 0,
            "top": 0,
            "drive": "main",
        },
        {
            "name": "strips",
            "type": "strips",
            "material": "belt",
            "centre": [-0.5, -0.6],
            "length": 1,
            "width": 0.4,
            "heading": 30,
            "top": 0.02,
            "drive": "strip",
            "count": 7,
            "strip_width": 0.03,
            "pitch": 0.06,
        },
    ],
    "walls": [{"name": "guide", "from": [0.1, -0.5], "to": [1.3, -0.2], "height": 0.1}],
    "start": {"position": [-0.3, -0.6], "heading": 30, "surface": "strips", "scatter": {}},
    "light_barriers": [
        {"name": "LS1", "from": [0, -0.7], "to": [-0.2, -0.2]},
        {"name": "LS2", "from": [1.8, -0.4], "to": [1.8, 0.4]},
    ],
    "regions": [{"x": [-0.2, 1.6]}],
    "end": {"x": [-1, 2], "y": [-1, 0.5], "duration": 2},
}
CONSIGNMENT = {
    "name": "C",
    "mass": 0.14,
    "outer": [0.275, 0.2, 0.02],
    "content": {"kind": "rigid", "size": [0.165, 0.125, 0.02]},
}
LOADERS = {
    "study": (load_study, STUDY),
    "screen": (load_screen, SCREEN),
    "twin": (load_twin_spec, TWIN),
    "tags": (load_tag_map, TAGS),
    "rig": (load_rig, RIG),
    "consignment": (load_consignment, CONSIGNMENT),
}


def _write(tmp_path, doc):
    path = tmp_path / "file.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _refused(tmp_path, kind, edit):
    load, base = LOADERS[kind]
    doc = yaml.safe_load(yaml.safe_dump(base))  # a deep copy
    edit(doc)
    path = _write(tmp_path, doc)
    with pytest.raises(ParcelfitError) as err:
        load(path)
    assert err.value.file == str(path)
    return err.value.where, err.value.message, err.value.fix


@pytest.mark.parametrize("kind", list(LOADERS))
def test_the_base_documents_load(tmp_path, kind):
    load, base = LOADERS[kind]
    assert load(_write(tmp_path, base)) is not None


CASES = {
    # kind, edit -> (where, message, fix)
    "study wrong type": (
        "study",
        lambda d: d.update(budget="many"),
        ("budget", "expected a whole number, got 'many'", "write a whole number such as 4"),
    ),
    "study unknown key": (
        "study",
        lambda d: d["reference"].update(speed_settin=2),
        ("reference", "unknown key 'speed_settin'", "did you mean 'speed_setting'?"),
    ),
    "study missing key": (
        "study",
        lambda d: d.pop("reference"),
        ("top level", "missing required key 'reference'", "add `reference:`"),
    ),
    "study out of range": (
        "study",
        lambda d: d.update(weights={"xy": -1}),
        ("weights.xy", "-1 is outside [0, None]", "use a value inside that range"),
    ),
    "study bounds not a pair": (
        "study",
        lambda d: d["parameters"].update(mu_d_BePa=[1, 2, 3]),
        (
            "parameters.mu_d_BePa",
            "expected [low, high] or {low, high, log}, got [1, 2, 3]",
            "write e.g. mu_d_BePa: [0.3, 0.6]",
        ),
    ),
    "study section not a mapping": (
        "study",
        lambda d: d.update(simulator=["python"]),
        (
            "simulator",
            "expected a mapping of keys to values, got list",
            "write it as `key: value` lines",
        ),
    ),
    "study backend needs its key": (
        "study",
        lambda d: d["simulator"].pop("factory"),
        ("simulator", "the python backend needs 'factory'", "add `factory:`"),
    ),
    "study tpe takes no settings": (
        "study",
        lambda d: d.update(optimizer={"sampler": "tpe", "ucb_lambda": 2}),
        (
            "optimizer",
            "unknown key 'ucb_lambda'",
            "the tpe sampler takes no settings but `sampler`",
        ),
    ),
    "study initial design of a billion": (
        "study",
        lambda d: d.update(initial=1e9, budget=1e9),
        ("initial", "1000000000 is out of range", "use a whole number in [1, 10000]"),
    ),
    "study budget of a billion": (
        "study",
        lambda d: d.update(budget=1e9),
        ("budget", "1000000000 is out of range", "use a whole number in [1, 10000]"),
    ),
    "study batch of a million": (
        "study",
        lambda d: d.update(batch_size=10**6),
        ("batch_size", "1000000 is out of range", "use a whole number in [1, 256]"),
    ),
    "study validation every": (
        "study",
        lambda d: d.update(validation={"speed_setting": 2, "every": 10**6}),
        ("validation.every", "1000000 is out of range", "use a whole number in [1, 10000]"),
    ),
    "study placements": (
        "study",
        lambda d: d.update(cost={"kind": "ensemble", "placements": 10**5}),
        ("cost.placements", "100000 is out of range", "use a whole number in [1, 1000]"),
    ),
    "study case placements": (
        "study",
        lambda d: (
            d.pop("reference"),
            d.update(
                cost="ensemble",
                cases=[
                    {
                        "dataset": "data",
                        "rig": "R",
                        "consignment": "P",
                        "speed_setting": 1,
                        "placements": 5000,
                    }
                ],
            ),
        ),
        ("cases[0].placements", "5000 is out of range", "use a whole number in [1, 1000]"),
    ),
    "study workers": (
        "study",
        lambda d: d.update(executor={"kind": "local", "workers": 10**5}),
        ("executor.workers", "100000 is out of range", "use a whole number in [1, 256]"),
    ),
    "study speed setting": (
        "study",
        lambda d: d["reference"].update(speed_setting=10**30),
        (
            "reference.speed_setting",
            "1000000000000000000000000000000 is out of range",
            "use a whole number in [1, 1000]",
        ),
    ),
    "study candidates per ask": (
        "study",
        lambda d: d.update(optimizer={"n_samples": 1e9}),
        (
            "optimizer.n_samples",
            "1000000000 is out of range",
            "use a whole number in [10, 1000000]",
        ),
    ),
    "study optimizer setting of the wrong type": (
        "study",
        lambda d: d.update(optimizer={"ucb_lambda": "wide"}),
        ("optimizer.ucb_lambda", "expected a number, got 'wide'", "write a plain number"),
    ),
    "study budget below initial": (
        "study",
        lambda d: d.update(initial=16, budget=8),
        (
            "budget",
            "budget 8 is below initial 16: the study would stop before its initial design is "
            "complete",
            "raise budget to 16 or more, or lower initial",
        ),
    ),
    "screen select": (
        "screen",
        lambda d: d.update(select=10**4),
        ("select", "10000 is out of range", "use a whole number in [1, 100]"),
    ),
    "screen workers": (
        "screen",
        lambda d: d.update(executor={"workers": 10**4}),
        ("executor.workers", "10000 is out of range", "use a whole number in [1, 256]"),
    ),
    "twin runs": (
        "twin",
        lambda d: d["settings"].update(runs=1e9),
        ("settings.runs", "1000000000 is out of range", "use a whole number in [1, 1000]"),
    ),
    "twin seed": (
        "twin",
        lambda d: d.update(seed=2**64),
        ("seed", "18446744073709551616 is out of range", "use a whole number in [0, 4294967295]"),
    ),
    "tags image width": (
        "tags",
        lambda d: d["camera"].update(width=10**9),
        ("camera.width", "1000000000 is out of range", "use a whole number in [0, 100000]"),
    ),
    "rig speed setting 10**20": (
        "rig",
        lambda d: d["speeds"].update({10**20: {"main": 1, "strip": 1}}),
        (
            "speeds",
            "speed setting 100000000000000000000 must be an integer from 1 to 1000",
            "write e.g. `1: {main: 1.56}`",
        ),
    ),
    "study negative friction": (
        "study",
        lambda d: d["parameters"].update(mu_d_BePa=[-0.5, -0.1]),
        (
            "parameters.mu_d_BePa",
            "mu_d_BePa = -0.5 is outside its physical range [0, 2]",
            "give dynamic friction belt/packaging from 0 to 2 (dimensionless)",
        ),
    ),
    "study friction above 2": (
        "study",
        lambda d: d["parameters"].update(mu_d_BePa=[5, 9]),
        (
            "parameters.mu_d_BePa",
            "mu_d_BePa = 5 is outside its physical range [0, 2]",
            "give dynamic friction belt/packaging from 0 to 2 (dimensionless)",
        ),
    ),
    "study negative modulus": (
        "study",
        lambda d: d["parameters"].update(E_Pa={"low": 0.5, "high": 100}),
        (
            "parameters.E_Pa",
            "E_Pa = 0.5 N/mm^2 is outside its physical range [1, 100000] N/mm^2",
            "give Young's modulus packaging from 1 to 100000 N/mm^2",
        ),
    ),
    "study fixed negative stiffness": (
        "study",
        lambda d: d.update(fixed={"k_BePa": -5}),
        (
            "fixed.k_BePa",
            "k_BePa = -5 N/mm is outside its physical range [1, 100000] N/mm",
            "give contact stiffness belt/packaging from 1 to 100000 N/mm",
        ),
    ),
    "study mujoco negative damping": (
        "study",
        lambda d: d.update(
            simulator={"backend": "mujoco", "rig": "E3", "consignment": "KPBW"},
            parameters={"zeta_BePa": [-1, 1]},
        ),
        (
            "parameters.zeta_BePa",
            "zeta_BePa = -1 is outside its physical range [0.01, 5]",
            "give contact damping ratio belt/packaging from 0.01 to 5 (dimensionless)",
        ),
    ),
    "screen range outside the physical one": (
        "screen",
        lambda d: d["parameters"].update(E_Pa=[-100, 100]),
        (
            "parameters.E_Pa",
            "E_Pa = -100 N/mm^2 is outside its physical range [1, 100000] N/mm^2",
            "give Young's modulus packaging from 1 to 100000 N/mm^2",
        ),
    ),
    "screen fixed outside the physical range": (
        "screen",
        lambda d: d.update(fixed={"nu_Pa": 0.7}),
        (
            "fixed.nu_Pa",
            "nu_Pa = 0.7 is outside its physical range [0, 0.49]",
            "give Poisson's ratio packaging from 0 to 0.49 (dimensionless)",
        ),
    ),
    "study bound of 400 digits": (
        "study",
        lambda d: d["parameters"].update(mu_d_BePa=[0.3, 10**400]),
        (
            "parameters.mu_d_BePa.high",
            "expected a number, got <a whole number of about 401 digits>",
            "write a plain number",
        ),
    ),
    "rig region with a number for a key": (
        "rig",
        lambda d: d["regions"].append({"x": [0, 1], 0: [0, 1]}),
        (
            "regions[1]",
            "unknown region keys ['0', 'x']",
            "use either x and/or y (a box) or polygon",
        ),
    ),
    "rig polygon point of 400 digits": (
        "rig",
        lambda d: d["regions"].append({"polygon": [[0, 0], [1, 0], [10**400, 1]]}),
        (
            "regions[1]",
            "polygon must be a list of at least three [x, y] points in metres",
            "write polygon: [[0, -0.4], [1, -0.4], [1, 0.4]]",
        ),
    ),
    "tags distortion of 400 digits": (
        "tags",
        lambda d: d["camera"].update(distortion=[0, 0, 0, 10**400]),
        ("camera.distortion", None, "write [k1, k2, p1, p2, k3] (OpenCV's order)"),
    ),
    "study mujoco unknown rig": (
        "study",
        lambda d: d.update(simulator={"backend": "mujoco", "rig": "E9", "consignment": "KPBW"}),
        (
            "simulator.rig",
            "unknown rig 'E9'",
            "use one of E1, E2a, E2b, E3 or the path of a .yaml file",
        ),
    ),
    "study mujoco case on an unknown rig": (
        "study",
        lambda d: d.update(
            simulator={"backend": "mujoco", "rig": "E3", "consignment": "KPBW"},
            reference=None,
            cases=[{"dataset": "data", "speed_setting": 1}, {"rig": "B9", "speed_setting": 1}],
        ),
        (
            "cases[1].rig",
            "no rig named 'B9': a case's rig is a bundled rig, the simulator's rig or one of "
            "simulator.rigs",
            "name one of ['E1', 'E2a', 'E2b', 'E3'], or add the rig's file to simulator.rigs",
        ),
    ),
    "study mujoco case naming a rig file": (
        "study",
        lambda d: d.update(
            simulator={"backend": "mujoco", "rig": "E3", "consignment": "KPBW"},
            reference=None,
            cases=[{"dataset": "data", "rig": "B1.yaml", "speed_setting": 1}],
        ),
        (
            "cases[0].rig",
            None,
            "add the file to simulator.rigs and name its rig here, or "
            "leave rig out for the simulator's",
        ),
    ),
    "study mujoco reference on an unknown rig": (
        "study",
        lambda d: d.update(simulator={"backend": "mujoco", "rig": "E3", "consignment": "KPBW"}),
        (
            "reference.rig",
            "no rig named 'R': the reference's rig is a bundled rig, the simulator's rig or one "
            "of simulator.rigs",
            "name one of ['E1', 'E2a', 'E2b', 'E3'], or add the rig's file to simulator.rigs",
        ),
    ),
    "study mujoco missing rigs file": (
        "study",
        lambda d: d.update(
            simulator={
                "backend": "mujoco",
                "rig": "E3",
                "consignment": "KPBW",
                "rigs": ["B7.yaml"],
            },
            parameters={"mu_d_BePa": [0.3, 0.6]},
            reference={"dataset": "data", "speed_setting": 1},
        ),
        (
            "simulator.rigs[0]",
            None,
            "give the path of a rig .yaml file, relative to this file (bundled rigs need no entry)",
        ),
    ),
    "study python backend with rigs": (
        "study",
        lambda d: d["simulator"].update(rigs=["B1.yaml"]),
        ("simulator.rigs", "the python backend does not take rigs", None),
    ),
    "screen mujoco unknown consignment": (
        "screen",
        lambda d: d.update(simulator={"backend": "mujoco", "rig": "E3", "consignment": "XX"}),
        (
            "simulator.consignment",
            "unknown consignment type 'XX'",
            "use one of BW, KP, KPBW, PB or the path of a .yaml file",
        ),
    ),
    "screen parameter both screened and fixed": (
        "screen",
        lambda d: d.update(fixed={"E_Pa": 800}),
        (
            "fixed",
            "['E_Pa'] are both screened and fixed",
            "remove them from fixed, or from parameters",
        ),
    ),
    "screen parameter of all that is fixed": (
        "screen",
        lambda d: d.update(parameters="all", fixed={"E_Pa": 800}),
        (
            "fixed",
            "['E_Pa'] are both screened and fixed",
            "remove them from fixed, or from parameters (parameters: all takes every candidate: "
            "list the others instead)",
        ),
    ),
    "screen max full factors below the default min": (
        "screen",
        lambda d: d.update(max_full_factors=2),
        (
            "min_full_factors",
            "min_full_factors 3 (its default) exceeds max_full_factors 2",
            "give min_full_factors at most max_full_factors",
        ),
    ),
    "screen full factorial first over more than it keeps": (
        "screen",
        lambda d: d.update(
            parameters=["mu_d_BePa", "E_Pa", "mu_d_MePa"], stages=["full"], max_full_factors=2
        ),
        (
            "stages",
            "the first stage is a full factorial over 3 parameters, which keeps at most "
            "max_full_factors = 2 and has nothing to rank them by yet",
            "start with a fractional stage (stages: [fractional, full]), list at most 2 "
            "parameters, or set max_full_factors: 3 (8 runs)",
        ),
    ),
    "screen soft content as large as the full stage": (
        "screen",
        lambda d: d.update(
            soft_content=["E_Co", "zeta_Co"], max_full_factors=2, min_full_factors=2
        ),
        (
            "max_full_factors",
            "the soft content's stage would keep only its 2 parameters (max_full_factors 2), no "
            "survivor beside them",
            "set max_full_factors: 4 or more, or list fewer soft_content parameters",
        ),
    ),
    "screen min full factors above max": (
        "screen",
        lambda d: d.update(min_full_factors=5, max_full_factors=4),
        (
            "min_full_factors",
            "min_full_factors 5 exceeds max_full_factors 4",
            "give min_full_factors at most max_full_factors",
        ),
    ),
    "screen soft content on a rigid one": (
        "screen",
        lambda d: d.update(_on_e3_kpbw(), soft_content=["E_Co"]),
        (
            "soft_content",
            "soft_content ['E_Co'] on a consignment with a rigid content",
            "leave soft_content out, or screen a soft-content type (e.g. PB)",
        ),
    ),
    "screen speed setting the rig lacks": (
        "screen",
        lambda d: d.update(_on_e3_kpbw(speed_setting=3)),
        (
            "reference.speed_setting",
            "rig E3 has no speed setting 3 (test case E3/KPBW/3)",
            "use one of [1, 2], or add the setting to the rig's speeds",
        ),
    ),
    "study transfer speed setting the rig lacks": (
        "study",
        lambda d: d.update(_on_e3_kpbw(), transfer=[{"rig": "E1", "speed_setting": 4}]),
        (
            "transfer[0].speed_setting",
            "rig E1 has no speed setting 4 (test case E1/KPBW/4)",
            "use one of [1, 2, 3], or add the setting to the rig's speeds",
        ),
    ),
    "screen executor dask": (
        "screen",
        lambda d: d.update(executor={"kind": "dask"}),
        ("executor.kind", "unknown executor 'dask'", "use one of serial, local"),
    ),
    "screen wrong type": (
        "screen",
        lambda d: d.update(alpha="small"),
        ("alpha", "expected a number, got 'small'", "write a plain number"),
    ),
    "screen unknown key": (
        "screen",
        lambda d: d.update(centre_point=2),
        ("top level", "unknown key 'centre_point'", "did you mean 'centre_points'?"),
    ),
    "screen missing key": (
        "screen",
        lambda d: d["reference"].pop("dataset"),
        ("reference", "missing required key 'dataset'", "add `dataset:`"),
    ),
    "screen out of range": (
        "screen",
        lambda d: d.update(resolution=6),
        ("resolution", "6 is out of range", "use a whole number in [3, 5]"),
    ),
    "screen one parameter": (
        "screen",
        lambda d: d.update(parameters=["mu_d_BePa"]),
        (
            "parameters",
            "a screen needs at least two parameters",
            "list two or more (or write parameters: all)",
        ),
    ),
    "screen scheduler is not a screen key": (
        "screen",
        lambda d: d.update(executor={"kind": "local", "scheduler": "tcp://x:1"}),
        ("executor", "unknown key 'scheduler'", "known keys: kind, workers"),
    ),
    "twin wrong type": (
        "twin",
        lambda d: d["truth"]["BW"].update(mu_d_BePa="half"),
        ("truth.BW.mu_d_BePa", "expected a number, got 'half'", "write a plain number"),
    ),
    "twin unknown key": (
        "twin",
        lambda d: d["settings"].update(runz=3),
        ("settings", "unknown key 'runz'", "did you mean 'runs'?"),
    ),
    "twin missing key": (
        "twin",
        lambda d: d.pop("cases"),
        ("top level", "missing required key 'cases'", "add `cases:`"),
    ),
    "twin out of range": (
        "twin",
        lambda d: d["settings"].update(friction_cv=-0.1),
        ("settings.friction_cv", "-0.1 is outside [0, None]", "use a value inside that range"),
    ),
    "twin runs not whole": (
        "twin",
        lambda d: d["settings"].update(runs=2.5),
        ("settings.runs", "expected a whole number, got 2.5", "write a whole number such as 4"),
    ),
    "twin bad case": (
        "twin",
        lambda d: d["cases"].append("E1-BW-1"),
        ("cases[1]", None, "write RIG/CONSIGNMENT/SETTING"),
    ),
    "twin unknown rig": (
        "twin",
        lambda d: d["cases"].append("E9/BW/1"),
        (
            "cases[1]",
            "unknown rig 'E9'",
            "use one of E1, E2a, E2b, E3 or the path of a .yaml file",
        ),
    ),
    "twin speed setting the rig lacks": (
        "twin",
        lambda d: d.update(cases=["E1/BW/9"]),
        ("cases[0]", "rig E1 has no speed setting 9", "use one of [1, 2, 3]"),
    ),
    "twin unknown consignment": (
        "twin",
        lambda d: d.update(cases=["E1/XX/1"]),
        ("cases[0]", "unknown consignment type 'XX'", None),
    ),
    "twin truth outside the physical range": (
        "twin",
        lambda d: d["truth"]["BW"].update(mu_d_BePa=5),
        (
            "truth.BW.mu_d_BePa",
            "mu_d_BePa = 5 is outside its physical range [0, 2]",
            "give dynamic friction belt/packaging from 0 to 2 (dimensionless)",
        ),
    ),
    "twin truth of another content kind": (
        "twin",
        lambda d: d["truth"]["BW"].update(E_Co=0.1),
        ("truth.BW.E_Co", "parameter E_Co does not apply to rigid contents", None),
    ),
    "tags wrong type": (
        "tags",
        lambda d: d["parcel_tags"][5].update(offset="centre"),
        ("parcel_tags.5.offset", "expected two numbers [a, b], got 'centre'", "write [a, b]"),
    ),
    "tags unknown key": (
        "tags",
        lambda d: d["reference_tags"][0].update(angel=90),
        ("reference_tags.0", "unknown key 'angel'", "did you mean 'angle'?"),
    ),
    "tags missing key": (
        "tags",
        lambda d: d["light_barriers"][0].pop("to"),
        ("light_barriers[0]", "missing required key 'to'", "add `to:`"),
    ),
    "tags out of range": (
        "tags",
        lambda d: d["reference_tags"][0].update(size=3),
        ("reference_tags.0.size", "3 is outside [0.001, 2] m", "use a value inside that range"),
    ),
    "tags bad id": (
        "tags",
        lambda d: d["parcel_tags"].update({"five": {"size": 0.06}}),
        (
            "parcel_tags.five",
            "tag ids are whole numbers >= 0, got 'five'",
            "use the tag's id number as the key",
        ),
    ),
    "tags light barrier of no length": (
        "tags",
        lambda d: d["light_barriers"][0].update({"to": [0.2, -0.5]}),
        (
            "light_barriers[0]",
            "light barrier 'start' has no length: from [0.2, -0.5] to [0.2, -0.5]",
            "give its two ends in metres, at least 1 mm apart",
        ),
    ),
    "tags light barriers of one id": (
        "tags",
        lambda d: d["light_barriers"].append(
            {"id": "start", "from": [0.5, -0.5], "to": [0.5, 0.5]}
        ),
        (
            "light_barriers[1]",
            "two light barriers have the id 'start'",
            "give each barrier its own id",
        ),
    ),
    "tags two roles": (
        "tags",
        lambda d: d["parcel_tags"].update({0: {"size": 0.06}}),
        ("parcel_tags.0", "tag 0 is both a reference and a parcel tag", "give every tag one role"),
    ),
    "rig wrong type": (
        "rig",
        lambda d: d["surfaces"][0].update(length="long"),
        ("surfaces[0].length", "expected a number in m, got 'long'", "write a plain number"),
    ),
    "rig unknown key": (
        "rig",
        lambda d: d["walls"][0].update(heigth=0.1),
        ("walls[0]", "unknown key 'heigth'", "did you mean 'height'?"),
    ),
    "rig missing key": (
        "rig",
        lambda d: d["surfaces"][1].pop("pitch"),
        ("surfaces[1]", "missing required key 'pitch'", "add `pitch:`"),
    ),
    "rig out of range": (
        "rig",
        lambda d: d["start"].update(scatter={"heading": 100}),
        ("start.scatter.heading", "100 is outside [0.0, 90] deg", "use a value inside that range"),
    ),
    "rig missing section": (
        "rig",
        lambda d: d.pop("end"),
        ("top level", "missing required key 'end'", "add `end:`"),
    ),
    "rig key of another surface type": (
        "rig",
        lambda d: d["surfaces"][0].update(count=3),
        (
            "surfaces[0]",
            "unknown key 'count'",
            "known keys: " + ", ".join([*RIG["surfaces"][0], "nose_radius"]),
        ),
    ),
    "rig unknown surface type": (
        "rig",
        lambda d: d["surfaces"][0].update(type="chute"),
        ("surfaces[0].type", "unknown surface type 'chute'", "use one of belt, strips, rollers"),
    ),
    "rig speed setting 0": (
        "rig",
        lambda d: d["speeds"].update({0: {"main": 1}}),
        (
            "speeds",
            "speed setting 0 must be an integer from 1 to 1000",
            "write e.g. `1: {main: 1.56}`",
        ),
    ),
    "rig drive without a speed": (
        "rig",
        lambda d: d["surfaces"][0].update(drive="fast"),
        (
            "surfaces[0].drive",
            "drive 'fast' has no speed in setting(s) [1]",
            "add fast to every speed setting",
        ),
    ),
    "rig point of three": (
        "rig",
        lambda d: d["light_barriers"][1].update(to=[1.8, 0.4, 0]),
        (
            "light_barriers[1].to",
            "expected a point [x, y] in metres, got [1.8, 0.4, 0]",
            "write e.g. [0.5, -0.4]",
        ),
    ),
    "rig one light barrier": (
        "rig",
        lambda d: d["light_barriers"].pop(),
        (
            "light_barriers",
            "exactly two light barriers are needed",
            "list LS1 and LS2 in the order the parcel crosses them",
        ),
    ),
    "rig start on no surface": (
        "rig",
        lambda d: d["start"].update(surface="floor"),
        ("start.surface", "start.surface names no surface: 'floor'", "use one of main, strips"),
    ),
    "rig start off its surface": (
        "rig",
        lambda d: d["start"].update(position=[-0.5, -1.2]),
        (
            "start.position",
            "start.position [-0.5, -1.2] lies off its surface 'strips' (-0.300 m along and "
            "-0.520 m across from its centre; it spans -0.5 to +0.5 m along and +-0.2 m across)",
            "put the start over the start surface, or name the surface it lies on",
        ),
    ),
    "rig wall of no length": (
        "rig",
        lambda d: d["walls"][0].update({"to": [0.1, -0.5]}),
        (
            "walls[0]",
            "'guide' has no length: from [0.1, -0.5] to [0.1, -0.5]",
            "give its two ends in metres, at least 1 mm apart",
        ),
    ),
    "rig light barrier of no length": (
        "rig",
        lambda d: d["light_barriers"][1].update({"to": [1.8, -0.4]}),
        (
            "light_barriers[1]",
            "'LS2' has no length: from [1.8, -0.4] to [1.8, -0.4]",
            "give its two ends in metres, at least 1 mm apart",
        ),
    ),
    "rig light barrier in mm": (
        "rig",
        lambda d: d["light_barriers"][1].update({"from": [1800, -400], "to": [1800, 400]}),
        (
            "light_barriers[1]",
            "light barrier 'LS2' lies 1.8e+03 m outside the end box (x [-1.0, 2.0], y [-1.0, "
            "0.5]): no run can reach it",
            "give its ends in metres in the rig frame, within the end box",
        ),
    ),
    "rig right-aligned start outside the end box": (
        "rig",
        lambda d: (d["start"].update(align="right"), d["end"].update(x=[0.0, 2.0])),
        (
            "start.position",
            "start.position [-0.3, -0.6] lies outside the end box (x [0.0, 2.0], y [-1.0, 0.5]): "
            "every run would end before it began",
            "widen end.x and end.y to hold the start and the whole path, or move the start",
        ),
    ),
    "rig light barriers of one name": (
        "rig",
        lambda d: d["light_barriers"][1].update(name="LS1"),
        (
            "light_barriers[1].name",
            "both light barriers are named 'LS1'",
            "give each its own name (e.g. LS1 and LS2)",
        ),
    ),
    "rig surface in mm": (
        "rig",
        lambda d: d["surfaces"][0].update(centre=[1000, 0]),
        (
            "surfaces[0].centre",
            "surface 'main' lies 996 m outside the end box (x [-1.0, 2.0], y [-1.0, 0.5]): no run "
            "can reach it",
            "give its centre, length and width in metres in the rig frame",
        ),
    ),
    "rig start outside the end box": (
        "rig",
        lambda d: d["end"].update(x=[0.0, 2.0]),
        (
            "start.position",
            "start.position [-0.3, -0.6] lies outside the end box (x [0.0, 2.0], y [-1.0, 0.5]): "
            "every run would end before it began",
            "widen end.x and end.y to hold the start and the whole path, or move the start",
        ),
    ),
    "rig bad region": (
        "rig",
        lambda d: d["regions"].append({"x": [2, 1]}),
        (
            "regions[1]",
            "expected x as [min, max] in metres with min < max, got [2, 1]",
            "write e.g. x: [0.5, 1.2]",
        ),
    ),
    "rig end not increasing": (
        "rig",
        lambda d: d["end"].update(y=[1, -1]),
        ("end.y", "expected [min, max] with min < max, got [1, -1]", "write e.g. [0.5, 1.2]"),
    ),
    "consignment wrong type": (
        "consignment",
        lambda d: d.update(mass="heavy"),
        ("mass", "expected a number in kg, got 'heavy'", "write a plain number"),
    ),
    "consignment unknown key": (
        "consignment",
        lambda d: d["content"].update(knid="soft"),
        ("content", "unknown key 'knid'", "did you mean 'kind'?"),
    ),
    "consignment missing key": (
        "consignment",
        lambda d: d.pop("outer"),
        ("top level", "missing required key 'outer'", "add `outer:`"),
    ),
    "consignment out of range": (
        "consignment",
        lambda d: d.update(mass=1000),
        ("mass", "1000 is outside [0.001, 100] kg", "use a value inside that range"),
    ),
    "consignment size out of range": (
        "consignment",
        lambda d: d["content"].update(size=[6, 0.1, 0.01]),
        (
            "content.size",
            "expected [length, width, height] in metres (1 mm to 5 m), got [6, 0.1, 0.01]",
            "write e.g. [0.275, 0.20, 0.02]",
        ),
    ),
    "consignment unknown content kind": (
        "consignment",
        lambda d: d["content"].update(kind="liquid"),
        ("content.kind", "unknown content kind 'liquid'", "use one of rigid, soft"),
    ),
    "consignment content too big": (
        "consignment",
        lambda d: d["content"].update(size=[0.3, 0.1, 0.02]),
        (
            "content.size",
            "content (0.3, 0.1, 0.02) does not fit inside the outer dimensions (0.275, 0.2, 0.02)",
            "make the content shorter and narrower than the packed parcel",
        ),
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_refusal_names_the_file_the_key_and_the_fix(tmp_path, case):
    kind, edit, (where, message, fix) = CASES[case]
    got = _refused(tmp_path, kind, edit)
    assert got[0] == where and (fix is None or got[2] == fix)
    if message is not None:
        assert got[1] == message


def test_study_values_are_si_and_sections_take_their_defaults(tmp_path):
    doc = {**STUDY, "parameters": {"E_Pa": {"low": 200, "high": 1600, "log": True}}}
    doc.update(fixed={"t_Pa": 0.5}, validation=None, executor=None)
    study = load_study(_write(tmp_path, doc))
    dim = study.space.dims[0]
    assert (dim.name, dim.low, dim.high, dim.log) == ("E_Pa", 2e8, 1.6e9, True)
    assert study.fixed == {"t_Pa": 0.0005}
    assert (study.validation_setting, study.validate_every) == (None, 5)
    assert study.executor == {"kind": "local", "workers": None, "scheduler": None}
    assert dict(study.simulator) == SIM


def test_a_screen_is_si_immutable_and_holds_its_soft_content_ranges(tmp_path):
    doc = {**SCREEN, "fixed": {"t_Pa": 0.5}, "soft_content": ["E_Co"], "executor": "serial"}
    screen = load_screen(_write(tmp_path, doc))
    assert screen.executor == {"kind": "serial", "workers": None}  # the string shorthand
    assert screen.parameters == ("mu_d_BePa", "E_Pa")
    assert screen.ranges["E_Pa"] == (2e8, 1.6e9) and screen.fixed == {"t_Pa": 0.0005}
    assert list(screen.ranges) == ["mu_d_BePa", "E_Pa", "E_Co"]
    assert isinstance(screen.ranges, MappingProxyType)
    with pytest.raises(TypeError):
        screen.ranges["x"] = (0.0, 1.0)


def test_tag_map_values_are_si(tmp_path):
    doc = {**TAGS, "timing": {"exposure_ms": 4, "readout_ms": 15}}
    doc["reference_tags"] = {0: {"x": 0.1, "y": 0.2, "size": 0.08, "angle": 90}}
    tm = load_tag_map(_write(tmp_path, doc))
    assert tm.reference_tags[0].angle == pytest.approx(1.5707963267948966)
    assert (tm.exposure, tm.readout) == (0.004, 0.015)
    assert tm.camera is not None and tm.camera.distortion == (0.0,) * 5
    assert tm.barriers[0].start == (0.2, -0.5) and tm.barriers[0].end == (0.2, 0.5)


def test_a_tag_map_reads_a_barrier_s_name_as_its_id(tmp_path):
    doc = {**TAGS, "light_barriers": [{"name": "LS1", "from": [0.2, -0.5], "to": [0.2, 0.5]}]}
    tm = load_tag_map(_write(tmp_path, doc))
    assert tm.barriers[0].name == "LS1" and tm.barriers[0].end == (0.2, 0.5)
    doc["light_barriers"][0]["id"] = "start"
    with pytest.raises(ParcelfitError, match="both `id` and `name`"):
        load_tag_map(_write(tmp_path, doc))


def test_a_rig_file_is_si_and_takes_its_defaults(tmp_path):
    path = _write(tmp_path, RIG)
    rig = load_rig(path)
    main, strips = (
        Surface("main", "belt", "belt", (1.0, 0.0), 3.0, 0.8, 0.0, 0.0, "main", {}),
        Surface(
            "strips",
            "strips",
            "belt",
            (-0.5, -0.6),
            1.0,
            0.4,
            30.0,
            0.02,
            "strip",
            {"count": 7.0, "strip_width": 0.03, "pitch": 0.06},
        ),
    )
    assert rig == Rig(
        name="R",
        description="",
        speeds={1: {"main": 1.5, "strip": 1.6}},
        surfaces=(main, strips),
        walls=(Wall("guide", "metal", (0.1, -0.5), (1.3, -0.2), 0.1, 0.0, 0.003, 0.0),),
        start=StartPose((-0.3, -0.6), 30.0, "strips", (0.0, 0.0, 0.0)),
        barriers=(
            Barrier("LS1", (0.0, -0.7), (-0.2, -0.2)),
            Barrier("LS2", (1.8, -0.4), (1.8, 0.4)),
        ),
        regions=(Box(xmin=-0.2, xmax=1.6),),
        margin=0.0,
        end=EndCondition((-1.0, 2.0), (-1.0, 0.5), 2.0, 0.3),
        source=str(path),
    )
    counts = rig.surface("strips").extra.values()
    assert all(type(v) is float for v in counts)  # as before: numbers, counts included, are floats


def test_a_consignment_file_holds_its_values(tmp_path):
    path = _write(tmp_path, {**CONSIGNMENT, "description": "  a box  "})
    assert load_consignment(path) == Consignment(
        "C", "a box", 0.14, (0.275, 0.2, 0.02), "rigid", (0.165, 0.125, 0.02), str(path)
    )


def test_numbers_in_exponent_form_are_read_as_numbers(tmp_path):
    """``1e-6`` and ``2E5`` are floats (YAML 1.2), not the text PyYAML's YAML 1.1 makes of them,
    so a setting written that way is accepted; quoted text and words stay text."""
    from parcelfit.config import load_yaml

    path = tmp_path / "numbers.yaml"
    path.write_text("a: 1e-6\nb: 2E5\nc: 1.0e-6\nd: 12\ne: '1e-6'\nf: abc1e5\ng: -3e+2\n")
    assert load_yaml(path) == {
        "a": 1e-6,
        "b": 2e5,
        "c": 1e-6,
        "d": 12,
        "e": "1e-6",
        "f": "abc1e5",
        "g": -300.0,
    }
    spec = tmp_path / "spec.yaml"
    spec.write_text("cases: [E3/PB/1]\nsettings: {tracking_sd: 1e-3}\n")
    assert load_twin_spec(spec).settings.tracking_sd == 1e-3


# -- the YAML loader every file goes through (parcelfit.config.load_yaml) ----------------------


def _alias_bomb(levels: int = 9) -> str:
    """``parameters:`` holding nine nested anchors of nine ("billion laughs": 9^9 values)."""
    lines = ['  a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for prev, name in zip("abcdefgh", "bcdefghi"[: levels - 1], strict=False):
        lines.append(f"  {name}: &{name} [{', '.join([f'*{prev}'] * 9)}]")
    return "parameters:\n" + "\n".join(lines) + "\n"


def test_an_alias_bomb_is_refused_at_once_naming_the_line(tmp_path):
    import time

    doc = {k: v for k, v in STUDY.items() if k != "parameters"}
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False) + _alias_bomb())
    t0 = time.perf_counter()
    with pytest.raises(ParcelfitError) as err:
        load_study(path)
    assert time.perf_counter() - t0 < 1
    e = err.value
    # lines 11-19 hold a to i; the first alias in f (to e, of 66430 values) passes the limit
    assert (e.file, e.where) == (str(path), "line 16, column 10")
    assert e.message == "aliases (*name) expand the document to more than 100000 values"
    assert e.fix == "write the values out, or repeat fewer of them through aliases"


def test_a_few_aliases_are_fine_and_a_recursive_one_is_refused(tmp_path):
    from parcelfit.config import load_yaml

    path = tmp_path / "a.yaml"
    path.write_text("r: &r [0.3, 0.6]\ns: *r\nbase: &b {x: 1}\nd: {<<: *b, y: 2}\n")
    assert load_yaml(path) == {
        "r": [0.3, 0.6],
        "s": [0.3, 0.6],
        "base": {"x": 1},
        "d": {"x": 1, "y": 2},
    }
    path.write_text("a: &x [1, *x]\n")
    with pytest.raises(ParcelfitError) as err:
        load_yaml(path)
    assert (err.value.where, err.value.message) == (
        "line 1, column 11",
        "the alias *x refers to a value that contains it",
    )


@pytest.mark.parametrize("kind", list(LOADERS))
def test_a_key_written_twice_is_refused_naming_both_lines(tmp_path, kind):
    load, base = LOADERS[kind]
    path = _write(tmp_path, base)
    text = path.read_text()
    first = text.splitlines()[0]  # the first top-level key, written again at the end
    path.write_text(text + first + "\n")
    with pytest.raises(ParcelfitError) as err:
        load(path)
    key = first.split(":")[0]
    n = len(text.splitlines()) + 1
    assert err.value.file == str(path) and err.value.where == f"line {n}, column 1"
    assert err.value.message == (
        f"the key {key!r} is written twice (lines 1 and {n}); YAML would keep only the last value"
    )
    assert err.value.fix == "delete one of the two, or merge them"


def test_a_key_written_twice_inside_a_section_and_as_equal_numbers(tmp_path):
    from parcelfit.config import load_yaml

    path = tmp_path / "a.yaml"
    path.write_text("speeds:\n  1: {main: 1}\n  01: {main: 2}\n")
    with pytest.raises(ParcelfitError, match=r"the key 1 is written twice \(lines 2 and 3\)"):
        load_yaml(path)


@pytest.mark.parametrize(
    ("text", "where", "message"),
    [
        (
            "a: " + "[" * 60 + "]" * 60 + "\n",
            "line 1, column 53",  # the 50th bracket: the mapping is the first level
            "values nested more than 50 levels deep",
        ),
        (
            "d: 2024-13-45\n",
            "line 1, column 4",
            "cannot read the value '2024-13-45' (month must be in 1..12)",
        ),
        ("n: " + "9" * 5000 + "\n", "line 1, column 4", None),
    ],
)
def test_values_pyyaml_cannot_construct_are_refused_with_the_line(tmp_path, text, where, message):
    from parcelfit.config import load_yaml

    path = tmp_path / "a.yaml"
    path.write_text(text)
    with pytest.raises(ParcelfitError) as err:
        load_yaml(path)
    assert err.value.where == where and err.value.file == str(path)
    if message is not None:
        assert err.value.message == message
    assert len(str(err.value)) < 400


def test_a_non_utf8_byte_is_named_by_its_offset_in_the_file(tmp_path):
    from parcelfit.config import load_yaml

    path = tmp_path / "a.yaml"
    path.write_bytes(b"# " + b"x" * 20000 + b"\nname: caf\xe9\n")
    with pytest.raises(ParcelfitError) as err:
        load_yaml(path)
    assert err.value.message == "not UTF-8 text (byte 20012: b'\\xe9')"


def test_a_refusal_quotes_a_big_value_on_one_short_line(tmp_path):
    """The message quotes at most 80 characters of what was written, on one line."""
    big = [0.1 * k for k in range(5000)]
    where, message, _ = _refused(tmp_path, "study", lambda d: d["parameters"].update(mu_d_BePa=big))
    assert where == "parameters.mu_d_BePa"
    assert (
        message
        == "expected [low, high] or {low, high, log}, got [0.0, 0.1, 0.2, 0.30000000000000004, 0.4, 0.5, ...]"
    )
    text = "many\nlines\u2028" * 1000
    where, message, _ = _refused(tmp_path, "study", lambda d: d.update(budget=text))
    assert (where, message) == (
        "budget",
        "expected a whole number, got 'many\\nlines\\u2028many\\nlines\\u20...any\\nlines\\u2028many\\nlines\\u2028'",
    )


def test_a_rendered_error_is_one_line_whatever_its_parts_hold():
    err = ParcelfitError("a\nb" + "x" * 1000, file="f\u2028g.yaml", where="k\r", fix="do\u0085it")
    assert str(err) == "f\\u2028g.yaml: k\\r: a\\nb" + "x" * 393 + "... Fix: do\\x85it"
    assert len(str(err).splitlines()) == 1


def test_every_catalogue_parameter_has_a_physical_range_holding_its_screening_ranges():
    from parcelfit.sim.params import CATALOGUE

    for p in CATALOGUE:
        lo, hi = p.physical
        assert 0 <= lo < hi, p.name  # no parameter of the catalogue is negative
        if p.name.startswith(("k_", "E_", "t_", "m_")):
            assert lo > 0, p.name  # stiffness, moduli, thickness, mass: positive
        if p.name.startswith("mu_"):
            assert hi <= 2, p.name
        for r in p.ranges.values():
            assert lo <= r.low < r.high <= hi and r.low <= r.default <= r.high, p.name


def test_a_start_is_on_its_surface_as_far_as_its_longest_strip_reaches_and_within_1_cm():
    import math
    from pathlib import Path

    import numpy as np

    from parcelfit.sim.mujoco.rig import parse_rig

    root = Path(__file__).resolve().parents[1]
    file = root / "examples" / "e3-variants" / "E3-staggered.yaml"
    doc = yaml.safe_load(file.read_text())
    rig = parse_rig(doc, str(file))
    strips = next(s for s in rig.surfaces if s.name == rig.start.surface)
    assert strips.end_heading is not None  # strips of different lengths
    u = np.array([math.cos(math.radians(strips.heading)), math.sin(math.radians(strips.heading))])
    n = np.array([-u[1], u[0]])
    centre = np.asarray(strips.centre)
    longest = max(strips.parts(), key=lambda p: float((p[1] - centre) @ u) + p[2] / 2)
    end = longest[1] + u * longest[2] / 2  # the downstream end of the longest strip
    doc["start"].pop("align", None)
    side = centre + n * strips.width / 2
    # along: as far as the longest strip and 1 cm beyond; across: 1 cm beyond the side
    for point, direction, offset, ok in (
        (end, u, -0.1, True),
        (end, u, 0.009, True),
        (end, u, 0.011, False),
        (side, n, 0.009, True),
        (side, n, 0.011, False),
    ):
        doc["start"]["position"] = [float(v) for v in point + offset * direction]
        if ok:
            parse_rig(doc, str(file))
        else:
            with pytest.raises(ParcelfitError, match="lies off its surface"):
                parse_rig(doc, str(file))
