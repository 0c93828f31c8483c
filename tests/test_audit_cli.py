"""`skyref audit` end to end: a small Bruneton 2017 table audited directly, the same tables
audited as if computed elsewhere (--tables, the paper's texture layout), and an analytic model."""

import json

import numpy as np

SCENE = """
name = "tiny"
[atmosphere]
preset = "bruneton2017"
[sun]
zenith_deg = 40.0
azimuth_deg = 90.0
[camera]
type = "equirectangular"
width = 16
height = 8
[spectral]
wavelengths = [680.0, 550.0, 440.0]
[render]
passes = 4
estimator = "delta_tracking"    # the audit is the subject: the baseline's kernels compile in seconds
"""
SMALL = ["r_size=4", "mu_size=16", "mu_s_size=4", "nu_size=2", "scattering_orders=2",
         "transmittance_width=32", "transmittance_height=8", "irradiance_width=16", "irradiance_height=4"]


def test_audit_cli_and_external_tables_agree(mi, tmp_path, monkeypatch, capsys):
    from skyref.atmosphere import preset
    from skyref.cli import main
    from skyref.lut import lut_method

    monkeypatch.chdir(tmp_path)
    (tmp_path / "tiny.toml").write_text(SCENE)
    options = [arg for option in SMALL for arg in ("--option", option)]
    common = ["audit", "--method", "bruneton2017", "--scene", "tiny.toml", "--max-spp", "256", "-q"]
    assert main(common + options + ["-o", "direct"]) == 0
    printed = capsys.readouterr().out
    assert "| sky |" in printed and "report: direct/report.md" in printed

    method = lut_method("bruneton2017", preset("bruneton2017"), [680.0, 550.0, 440.0],
                        **{k: int(v) for k, v in (o.split("=") for o in SMALL)})
    method.precompute()
    np.savez(tmp_path / "tables.npz", **method.tables())
    assert main(common + ["--tables", "tables.npz", "--option", "mu_s_size=4", "-o", "external"]) == 0

    direct = json.load(open(tmp_path / "direct" / "summary.json"))
    external = json.load(open(tmp_path / "external" / "summary.json"))
    assert external["precompute_s"] == 0.0  # nothing was recomputed
    for region, row in direct["statistics"].items():
        for metric in ("luminance", "spectral", "delta_e"):
            for stat in ("mean", "rms", "p95", "max"):
                assert np.isclose(external["statistics"][region][metric][stat], row[metric][stat], rtol=1e-6), \
                    (region, metric, stat)


def test_audit_cli_rejects_an_unknown_method(tmp_path, monkeypatch, capsys):
    from skyref.cli import main

    monkeypatch.chdir(tmp_path)
    (tmp_path / "tiny.toml").write_text(SCENE)
    assert main(["audit", "--method", "bruneton2018", "--scene", "tiny.toml"]) == 2
    assert "--method = 'bruneton2018'" in capsys.readouterr().err
    assert main(["audit", "--method", "preetham1999", "--scene", "tiny.toml", "--tables", "x.npz"]) == 2
    assert "--tables" in capsys.readouterr().err


def test_audit_cli_audits_an_analytic_model(mi, tmp_path, monkeypatch, capsys):
    """An analytic model joins the audit like a LUT method; its options pass through --option."""
    from skyref.cli import main

    monkeypatch.chdir(tmp_path)
    (tmp_path / "tiny.toml").write_text(SCENE)
    assert main(["audit", "--method", "nishita1993", "--scene", "tiny.toml", "--option", "shells=8",
                 "--max-spp", "256", "-q", "-o", "nishita"]) == 0
    assert "| sky |" in capsys.readouterr().out
    summary = json.load(open(tmp_path / "nishita" / "summary.json"))
    # Single scattering only: darker than the truth's full multiple scattering on average.
    assert summary["statistics"]["sky"]["luminance"]["mean"] < 0.0
