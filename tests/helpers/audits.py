"""Changes for audit runs in tests: a control the audit must find and a planted wrong documentation it must report."""

#: A tight indirect clamp: biased by design (a control), found in the corner scene within 2 passes.
TIGHT = """
[[change]]
name = "tight_clamp"
setting = "cycles.sample_clamp_indirect"
reference = ["cycles.sample_clamp_indirect=0"]
test = ["cycles.sample_clamp_indirect=0.05"]
documented = "bias"
samples = 1
why = "a tight indirect clamp, a control"
"""
#: A tight direct clamp wrongly documented as noise-only: a finding the audit must report.
PLANTED = """
[[change]]
name = "planted"
setting = "cycles.sample_clamp_direct"
reference = ["cycles.sample_clamp_direct=0"]
test = ["cycles.sample_clamp_direct=0.05"]
documented = "noise"
samples = 1
why = "a direct clamp said to change only the noise"
"""
