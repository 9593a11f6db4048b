"""Simulated devices, each beside the interface it fakes: the camera (`camera`, the ``sim`` camera backend, and
`gige`, the same camera served over GigE Vision), the serial light and spectrometer (`serial_instruments`,
behind real pseudo-terminals by `serial_sim`), the Ocean Insight spectrometer behind seabreeze's own class
(`ocean_insight`). The real drivers never import them."""
