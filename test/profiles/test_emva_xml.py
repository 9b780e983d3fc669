"""The EMVA reference implementation's results XML as a datasheet: the real CCD crop's XML (written by emva1288
1.0.2) gives the profile that `characterize` makes from the crop's images, and files that are not such an XML are
refused with the reason."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from noise_monitor.cli import main
from noise_monitor.physics import NoiseModel
from noise_monitor.profiles import DatasheetError, profile_from_datasheet, round_trip
from noise_monitor.profiles.characterize import characterize, datasheet_from_result
from noise_monitor.profiles.emva_images import read_image_set
from noise_monitor.profiles.emva_xml import datasheet_from_results

CCD = Path(__file__).resolve().parents[1] / "data" / "emva1288_ccd"
XML = CCD / "results.xml"
REFERENCE = json.loads((CCD / "reference.json").read_text())["results"]
DSNU_EXPOSURE_S = 5.16e-3  # the descriptor's dark spatial set: "d 5160000.0" (ns), 8 images
CONDITIONS = {"sensor_type": "ccd", "bit_depth": 12, "pixel_size_um": 7.4, "temperature_c": 30.0}
FLAGS = ["--sensor-type", "ccd", "--bit-depth", "12", "--pixel-size-um", "7.4", "--temperature-c", "30"]


@pytest.fixture(scope="module")
def from_images():
    """What `characterize` measures on the crop's images (its pixel-scale PRNU and DSNU: 5x5 high-pass)."""
    return characterize(read_image_set(CCD, temperature_c=30.0))


def test_the_xml_figures_are_the_reference_implementations(from_images):
    ds, notes = datasheet_from_results(XML, **CONDITIONS, dsnu_exposure_s=DSNU_EXPOSURE_S)
    assert ds.system_gain_dn_per_e == REFERENCE["K"] and ds.saturation_capacity_e == REFERENCE["u_e_sat"]
    assert ds.dark_current_e_per_s == REFERENCE["u_I_mean"] and ds.quantum_efficiency_pct == REFERENCE["QE"]
    # sigma_d at zero exposure, taken to the DSNU's exposure with the dark signal's shot noise
    assert ds.temporal_dark_noise_e == pytest.approx(math.hypot(REFERENCE["sigma_d"], math.sqrt(
        REFERENCE["u_I_mean"] * DSNU_EXPOSURE_S)), rel=1e-12)
    assert ds.measurement_exposure_s == DSNU_EXPOSURE_S and ds.dark_current_temperature_c == 30.0
    assert any("at zero exposure" in n for n in notes)
    # the non-uniformities' pixel components (PRNU1288 0.261 % in all), what characterize's high-pass reads too
    hpf = from_images["figures"]
    assert ds.prnu_pct != REFERENCE["PRNU1288"] and ds.prnu_pct == pytest.approx(hpf["prnu_hpf_pct"]["value"], rel=0.03)
    assert ds.dsnu_e == hpf["dsnu_hpf_e"]["value"] == 0.0  # emva1288: NaN, a negative pixel variance
    assert any("PRNU 0.2551 %, the pixel component (total 0.2615)" in n for n in notes)
    rows = {r["field"]: r for r in round_trip(ds, profile_from_datasheet(ds).profile)}
    for field in ("system_gain_dn_per_e", "temporal_dark_noise_e", "dark_current_e_per_s@30C", "prnu_pct"):
        assert rows[field]["ok"], field
    plain, _ = datasheet_from_results(XML, **CONDITIONS)  # no DSNU exposure: sigma_d as it is
    assert plain.temporal_dark_noise_e == REFERENCE["sigma_d"] and plain.measurement_exposure_s == 0.0


def test_the_xml_profile_predicts_the_noise_of_the_profile_made_from_the_images(from_images):
    """Two implementations on the same measurement: emva1288's figures through the XML, and `characterize` on the
    crop's images; their models' temporal noise (read noise, K, dark current) agrees within 0.3 % and their total
    noise (with the pixel PRNU) within 1 % over the signal range at 0 and 12 dB."""
    xml = profile_from_datasheet(datasheet_from_results(XML, **CONDITIONS, dsnu_exposure_s=DSNU_EXPOSURE_S)[0]).profile
    made, _ = datasheet_from_result(from_images, "crop", "ccd", 7.4)
    assert made is not None
    images = profile_from_datasheet(made).profile
    assert xml.values["full_well_e"] == pytest.approx(images.values["full_well_e"], rel=1e-4)
    signal = np.array([5.0, 20.0, 80.0, 160.0, 230.0])
    for gain_db, exposure_s, temp_c in ((0.0, 0.01, 30.0), (12.0, 0.1, 45.0)):
        pred = [NoiseModel(extra=p.effects).predict(signal, p.metadata(gain_db=gain_db, exposure_time_s=exposure_s,
                                                                      sensor_temperature_c=temp_c))
                for p in (xml, images)]
        temporal = [np.sqrt(p["pn"] ** 2 + p["dcsn"] ** 2 + p["rn"] ** 2) for p in pred]
        assert np.allclose(temporal[0], temporal[1], rtol=3e-3), (gain_db, temporal)
        assert np.allclose(pred[0]["total"], pred[1]["total"], rtol=1e-2)


def test_the_cli_reads_an_xml_with_the_conditions_it_does_not_hold(tmp_path, capsys):
    out = tmp_path / "ccd.yaml"
    assert main(["profile", "from-emva", str(XML), "--out", str(out), *FLAGS, "--dsnu-exposure-s", "0.00516",
                 "--name", "basler-ccd", "--dark-offset-dn", "14.7"]) == 0
    printed = capsys.readouterr().out
    assert "profile 'basler-ccd'" in printed and "temporal_dark_noise_e" in printed
    assert "black_level_dn: 0.91" in out.read_text()
    assert main(["profile", "from-emva", str(XML), "--out", str(out), "--sensor-type", "ccd"]) == 2
    err = capsys.readouterr().err
    assert "--bit-depth, --pixel-size-um, --temperature-c" in err and len(err.strip().splitlines()) == 1
    example = share_example()
    assert main(["profile", "from-emva", str(example), "--out", str(out), "--bit-depth", "12"]) == 2
    assert "for a results XML only" in capsys.readouterr().err


def share_example() -> Path:
    from noise_monitor.paths import share_dir

    return share_dir() / "config" / "datasheets" / "example_cmos_emva.yaml"


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("<results>", '<!DOCTYPE r [<!ENTITY a "aaaa">]>\n<results>'), "DOCTYPE or entities"),
    (lambda t: t.replace("<unit>$DN/e^-$</unit>", "<unit>$e^-/DN$</unit>", 1), "K is in e-/DN"),
    (lambda t: t.replace("<K>", "<Kx>").replace("</K>", "</Kx>"), "no K"),
    (lambda t: t[: len(t) // 2], "not well-formed"),
    (lambda t: t.replace("<value>33.344537733086334</value>", "<value>nan</value>"), "u_I_mean is missing"),
    (lambda t: t.replace("<value>33.344537733086334</value>", "<value>-4.0</value>"), "negative"),
    (lambda t: t.replace("<value>0.28809951065520567</value>", "<value>0.28x</value>"), "is not a number"),
])
def test_what_is_not_an_emva1288_results_xml_is_refused_with_the_reason(tmp_path, edit, message):
    bad = tmp_path / "bad.xml"
    bad.write_text(edit(XML.read_text()))
    with pytest.raises(DatasheetError, match=message):
        datasheet_from_results(bad, **CONDITIONS)


def test_case_and_the_descriptors_exposure_unit(tmp_path):
    """emva1288's reader takes tags in any case (some writers use CamelCase); a descriptor in us made its per-ns dark
    current 1000x too high."""
    lower = tmp_path / "lower.xml"
    lower.write_text(XML.read_text().replace("<K>", "<k>").replace("</K>", "</k>"))
    assert datasheet_from_results(lower, **CONDITIONS)[0].system_gain_dn_per_e == REFERENCE["K"]
    us, _ = datasheet_from_results(XML, **CONDITIONS, exposure_unit="us")
    assert us.dark_current_e_per_s == pytest.approx(REFERENCE["u_I_mean"] * 1e-3, rel=1e-12)
    bad_dark = tmp_path / "dark.xml"  # an 8-bit camera whose dark signal did not move: emva1288's slope < 0
    bad_dark.write_text(XML.read_text().replace("<value>33.344537733086334</value>", "<value>-583870.06</value>"))
    zero, notes = datasheet_from_results(bad_dark, **CONDITIONS, dark_current_e_per_s=0.0)
    assert zero.dark_current_e_per_s == 0.0 and "dark current 0 e-/s as given, not the XML's" in notes[0]
    for bad in (-1.0, 0.0, math.nan, 1e4):
        with pytest.raises(DatasheetError, match="the DSNU's exposure must be in"):
            datasheet_from_results(XML, **CONDITIONS, dsnu_exposure_s=bad)
