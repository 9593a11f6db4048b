"""Helpers shared by the tests: paths (`paths`), sweep plans (`plans`), running `uwlab` as a subprocess
(`cli_process`), the explorer server (`explorer_process`) and simulated GigE cameras (`gige_server`)."""
