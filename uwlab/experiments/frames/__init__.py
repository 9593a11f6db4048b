"""Statistics of stacks of frames, shared by acquisition, datasets and EMVA 1288 analysis: the streaming stack
statistics (`stack`) and the spatial non-uniformity split of a mean image (`nonuniformity`, EMVA 1288 §8.1)."""
