"""One declaration of every setting: each config field with a flag makes its command-line option,
and that option sets that key, and nothing else; the TOML writer and reader keep every value."""

from __future__ import annotations

import dataclasses

import click
import pytest

from mocap_exaggerate.config import PipelineConfig, load_preset, preset_names
from mocap_exaggerate.core.settings import flagged_settings
from mocap_exaggerate_cli.exaggerate import exaggerate
from mocap_exaggerate_cli.options import config_from_options, setting_param

from .helpers import SAMPLE_CLIPS

#: A word each flag takes, and the value the setting then holds (None: the choice's own word).
#: A new flag without a row here fails `test_every_flag_has_a_case`: add one.
SAMPLES = {
    "extrapolate.sigma": ("18f", "18f"), "extrapolate.omega": ("3.5", 3.5),
    "extrapolate.weights": ("Hips=0", (("Hips", 0.0),)),
    "correct.threshold": ("0.07", 0.07), "correct.delta": ("0.3", 0.3), "correct.max_stretch": ("1.2", 1.2),
    "correct.max_iter": ("77", 77), "subjoints.per_link": ("3", 3), "subjoints.sublink_length": ("3%", "3%"),
    "springs.stiffness": ("99", 99.0), "springs.link_stiffness": ("88", 88.0), "springs.damping": ("5", 5.0),
    "springs.blend": ("0.25", 0.25), "springs.max_stretch": ("1.3", 1.3), "input.fps": ("60", 60.0), "input.clip": ("Run", "Run"),
    "glb.units": ("cm", "cm"),
    ".stretch": ("left_arm:10-20:2", None), ".target": ("lHand@10", None),
}


def _given(option: str, word: str | None) -> list[str]:
    return [option] if word is None else [option, word]


def _cases():
    """(key, words on the command line, the value the key must then hold) for every declared flag."""
    default = load_preset("cartoon")
    for block, key, flag in flagged_settings(PipelineConfig):
        name = f"{block}.{key}"
        current = getattr(getattr(default, block), key) if block else getattr(default, key)
        if flag.sets is not None:
            yield name, [flag.option], flag.sets
        elif "/" in flag.option:
            on, off = flag.option.split("/")
            yield name, [off if current else on], not current
        elif flag.choices is not None:
            words = list(flag.choices)
            values = flag.choices if isinstance(flag.choices, dict) else {w: w for w in words}
            word = next(w for w in words if values[w] != current)
            yield name, [flag.option, word], values[word]
        elif flag.path:
            yield name, [flag.option, "skin.npz" if key == "skin" else "map.txt"], "given"
        elif name in SAMPLES:
            word, value = SAMPLES[name]
            yield name, [flag.option, word], value
        else:
            yield name, [flag.option], "no sample"


CASES = list(_cases())


def test_every_flag_has_a_case():
    missing = [name for name, _, value in CASES if value == "no sample"]
    assert not missing, f"add a sample word for {missing} to SAMPLES"
    assert len(CASES) >= 35


@pytest.mark.parametrize("name, words, expected", CASES, ids=[c[0] for c in CASES])
def test_each_flag_sets_its_key_and_nothing_else(name, words, expected, tmp_path):
    block, _, key = name.partition(".")
    (tmp_path / "skin.npz").write_bytes(b"")
    (tmp_path / "map.txt").write_text("Hips = Hips\n")
    words = [str(tmp_path / w) if w in ("skin.npz", "map.txt") else w for w in words]
    if key == "joint_map":  # a joint map pairs with a skin
        words += ["--skin", str(tmp_path / "skin.npz")]
    argv = [str(SAMPLE_CLIPS[0]), "-o", str(tmp_path / "out"), *words]
    context = exaggerate.make_context("exaggerate", list(argv))  # click takes the words off the list
    assert context.params[setting_param(block, key)] not in (None, ())
    _, config = config_from_options(context.params)
    _, plain = config_from_options(exaggerate.make_context("exaggerate", list(argv[:3])).params)
    value = getattr(getattr(config, block), key) if block else getattr(config, key)
    if expected == "given":
        assert value.endswith(words[1])
    elif key in ("stretch", "target"):
        assert len(value) == 1 and value[0].to_dict()  # parsed into the list
    else:
        assert value == expected
    # Nothing else moved: the two configs differ in this key alone (and the joint map's skin).
    changed = {f"{b}.{k}" for b, table in config.to_dict().items() if isinstance(table, dict)
               for k in table if table[k] != plain.to_dict().get(b, {}).get(k)}
    changed |= {k for k in ("stretch", "target") if getattr(config, k) != getattr(plain, k)}
    assert changed - ({"glb.skin"} - {name}) == {name.lstrip(".")}


def test_no_setting_option_is_written_by_hand():
    """Every option of ``exaggerate`` that sets a setting comes from the setting's declaration:
    the options left are about files and the run, not the pipeline."""
    declared = {setting_param(block, key) for block, key, _ in flagged_settings(PipelineConfig)}
    own = {p.name for p in exaggerate.params if isinstance(p, click.Option)} - declared
    assert own == {"output", "name", "overwrite", "trails_path", "path_file", "preset", "config_file", "settings",
                   "verbose", "quiet"}


@pytest.mark.parametrize("preset", preset_names())
def test_toml_writer_and_reader_keep_every_value(preset):
    config = dataclasses.replace(
        load_preset(preset),
        extrapolate=dataclasses.replace(load_preset(preset).extrapolate, weights=(("Left*", 0.5), ("Hips", 0.0))),
    )
    config = dataclasses.replace(config, subjoints=dataclasses.replace(config.subjoints, groups=(("a", "b", "c"),),
                                                                       rigid=("Finger*",)))
    again = PipelineConfig.from_toml(config.to_toml(preset=preset))
    assert again == config
    assert "[extrapolate.weights]" in config.to_toml()  # a table, as declared, not an array of pairs
