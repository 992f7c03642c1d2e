"""The command line: measure speed and memory, the model-error term, probes of every flag."""
