"""The plugin reference lists every option: each integrator's docstring table
(``.. pluginparameters::``, shown by ``docs/reference/plugins.rst``) has a row for every
property its classes read, and no row for one they do not."""
from __future__ import annotations

import inspect
import re

import pytest

import draaw_mi  # noqa: F401
from draaw_mi.integrators import v1, v2, v3, v4
from draaw_mi.sdf.tracer import TracerOptions

# a property read: parse_int(props, PLUGIN, "name" ...), props.get("name"), props["name"], and
# the SDF tracer's (prop, key, conversion) triples
READ = re.compile(r'parse_\w+\(props, [^,]+, "(\w+)"|props\.get\("(\w+)"|props\["(\w+)"\]'
                  r'|\("(sdf_\w+)", "\w+", \w+\)')
BY_MITSUBA = {"max_depth", "rr_depth", "hide_emitters"}   # read by Mitsuba's ADIntegrator too


def options_read(cls) -> set[str]:
    src = "".join(inspect.getsource(k) for k in cls.__mro__ if k.__module__.startswith("draaw_mi"))
    src += inspect.getsource(TracerOptions)
    return {next(g for g in m.groups() if g) for m in READ.finditer(src)}


@pytest.mark.parametrize("cls", [v1.DraawV1Integrator, v2.DraawV2Integrator,
                                 v3.DraawV3Integrator, v4.DraawV4Integrator],
                         ids=["v1", "v2", "v3", "v4"])
def test_every_option_read_has_a_row_and_every_row_is_read(cls):
    rows = re.findall(r"^\s+\* - (\w+)$", cls.__doc__, re.M)
    assert len(rows) == len(set(rows)), rows                   # no row twice
    read = options_read(cls)
    assert {"sdf_epsilon", "sdf_max_steps", "sdf_relaxation", "max_depth"} <= read | BY_MITSUBA
    assert sorted(read - set(rows)) == []                      # read, not documented
    assert sorted(set(rows) - read - BY_MITSUBA) == []         # documented, not read
