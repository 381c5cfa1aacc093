"""Input and output helpers: atomic writes and bounded reads (:mod:`.atomic`), the YAML
reader with positions (:mod:`.yamlio`), and the output-folder rules every writing command
follows (:mod:`.runfolder`: layout, manifest, lock, staging and swap)."""
