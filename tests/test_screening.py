import pandas as pd
import pytest
import yaml

from parcelfit.study.screening import load_screen, run_screen

from .fake_sim import write_reference_dataset


@pytest.mark.slow
def test_screen_finds_the_parameters_that_matter(tmp_path):
    write_reference_dataset(tmp_path / "data")
    doc = {
        "name": "fake-screen",
        "simulator": {"backend": "python", "factory": "tests.fake_sim:make"},
        "reference": {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1},
        # two parameters the analytic simulator responds to, four it ignores
        "parameters": {
            "mu_d_BePa": [0.3, 0.58],
            "mu_d_MePa": [0.15, 0.35],
            "E_Pa": [200, 1600],
            "nu_Pa": [0.2, 0.45],
            "t_Pa": [0.2, 1.0],
            "k_CoPa": [100, 1000],
        },
        "stages": ["fractional", "full"],
        "select": 4,
        "executor": {"kind": "local", "workers": 2},
    }
    path = tmp_path / "screen.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    events = []
    stages, selection = run_screen(load_screen(path), tmp_path / "out", progress=events.append)
    assert [s.kind for s in stages] == ["fractional", "full"]
    assert stages[0].factors == list(doc["parameters"]) and len(stages[0].analyses) == 2
    # the two significant parameters first, topped up to three by effect size (E_Pa's tiny effect)
    # for stage 2; the parameters with exactly no effect are never taken
    assert (
        set(stages[0].survivors[:2]) == {"mu_d_BePa", "mu_d_MePa"} and len(stages[0].survivors) == 3
    )
    assert stages[1].factors == stages[0].survivors
    assert set(selection["selected"][:2]) == {"mu_d_BePa", "mu_d_MePa"}
    third = selection["selected"][2]
    assert "(not significant)" in selection["reasons"][third]
    assert selection["parameters"]["mu_d_BePa"] == [0.3, 0.58]
    design = pd.read_csv(tmp_path / "out" / "stage1-design.csv")
    assert len(design) == 16 and (design["status"] == "ok").all()
    assert (tmp_path / "out" / "stage2-pareto-dtw_xy.png").is_file()
    assert (
        yaml.safe_load((tmp_path / "out" / "selection.yaml").read_text())["selected"]
        == selection["selected"]
    )
    counted = [(e.done, e.total) for e in events if e.done is not None]
    assert counted[:16] == [(k, 16) for k in range(1, 17)]  # stage 1's simulations, one by one
    assert {e.job for e in events} == {"screening"}
    # resumable: a rerun simulates nothing
    events.clear()
    run_screen(load_screen(path), tmp_path / "out", progress=events.append)
    assert not any(e.message.startswith("ok:") for e in events)


def _polybag_screen(tmp_path, **changes):
    """A screen file on the analytic simulator: one full factorial over three parameters, then
    the soft content's stage (E_Co, zeta_Co); ``changes`` replace its keys."""
    write_reference_dataset(tmp_path / "data")
    doc = {
        "name": "pb",
        "simulator": {"backend": "python", "factory": "tests.fake_sim:make"},
        "reference": {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1},
        "parameters": {"mu_d_BePa": [0.3, 0.58], "mu_d_MePa": [0.15, 0.35], "E_Pa": [200, 1600]},
        "stages": ["full"],
        "soft_content": ["E_Co", "zeta_Co"],
        "executor": {"kind": "local", "workers": 2},
        **changes,
    }
    path = tmp_path / "pb.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return load_screen(path)


@pytest.mark.slow
def test_polybag_third_stage_and_centre_points(tmp_path):
    stages, _ = run_screen(_polybag_screen(tmp_path, centre_points=2), tmp_path / "out")
    assert [s.kind for s in stages] == ["full", "full"]
    assert {"E_Co", "zeta_Co"} <= set(stages[1].factors)
    assert len(pd.read_csv(tmp_path / "out" / "stage1-design.csv")) == 8 + 2


def test_the_soft_content_stage_keeps_its_own_parameters_when_it_must_cut(tmp_path):
    """3 survivors and 2 soft-content parameters at max_full_factors 4: the stage keeps both of
    the content's and the 2 strongest survivors (it cut the list's end: the content's own)."""
    events = []
    screen = _polybag_screen(tmp_path, max_full_factors=4)
    stages, _ = run_screen(screen, tmp_path / "out", progress=events.append)
    first, second = stages
    assert len(second.factors) == 4 and {"E_Co", "zeta_Co"} <= set(second.factors)
    assert second.factors[:2] == first.survivors[:2]
    assert any("keeping the 2 strongest and the soft content's E_Co, zeta_Co" in e.message
               for e in events)  # fmt: skip


@pytest.mark.parametrize("consignment", ["PB", "KPBW"])
def test_all_parameters_come_from_the_consignments_content_kind(tmp_path, consignment):
    """``parameters: all`` is every catalogue candidate of the consignment's content kind but
    the content's own parameters (a soft content's are the soft_content stage's)."""
    from parcelfit.sim.mujoco import load_consignment
    from parcelfit.sim.params import content_parameters, parameters_for

    kind = load_consignment(consignment).content_kind
    doc = {
        "name": "all",
        "simulator": {"backend": "mujoco", "rig": "E3", "consignment": consignment},
        "reference": {"dataset": "data", "speed_setting": 1},
        "parameters": "all",
    }
    path = tmp_path / "screen.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    screen = load_screen(path)
    own = {p.name for p in content_parameters(kind)}
    assert screen.parameters == tuple(p.name for p in parameters_for(kind) if p.name not in own)
    assert len(screen.parameters) == 16
    assert own == ({"E_Co", "zeta_Co"} if kind == "soft" else set())
    assert not own & set(screen.parameters)


@pytest.mark.parametrize("missing", ["dataset", "case"])
def test_a_screen_without_its_data_names_the_screen_file_and_leaves_no_folder(tmp_path, missing):
    from parcelfit import ParcelfitError

    if missing == "case":
        write_reference_dataset(tmp_path / "data")
    doc = {
        "name": "s",
        "simulator": {"backend": "python", "factory": "tests.fake_sim:make"},
        "reference": {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 7},
        "parameters": {"mu_d_BePa": [0.3, 0.58], "E_Pa": [200, 1600]},
    }
    path = tmp_path / "screen.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.raises(ParcelfitError) as caught:
        run_screen(load_screen(path), tmp_path / "out")
    err = caught.value
    assert err.file == str(path)
    if missing == "dataset":
        assert err.where == "reference.dataset"
        assert err.message == f"R/P/7: its dataset {tmp_path / 'data'} holds no dataset.yaml"
    else:
        assert err.where == "reference"
        assert err.message.startswith("test case R/P/7 is not in dataset")
    assert not (tmp_path / "out").exists()
