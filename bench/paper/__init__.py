"""The paper's commands (paper.sh) and the assembly of results/paper/."""
