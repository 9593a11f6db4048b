"""EMVA 1288 workflow: streaming frame statistics, photon-transfer input from datasets and descriptor files,
the characterisation itself, its plots, sensor profiles written from it, and a simulated photon transfer."""
