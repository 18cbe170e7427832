"""A deterministic flaky agent for the trials test: the stub tasks' oracle,
except that on its n-th visit of a task (0-based, counted in a file of
$ARENA_FLAKY_DIR) it gives up at once when the task's pattern in
$ARENA_FLAKY_PATTERN (JSON: task name -> "P"/"F" per visit) says F: FAIL on a
feasible task, DONE on the infeasible one. Each visit is appended to
$ARENA_FLAKY_DIR/order.txt, so the test sees the order tasks came in."""

import json
import os

from oracle_agent import Oracle


class Flaky(Oracle):
    name = "flaky"

    def reset(self, task):
        super().reset(task)
        folder = os.environ["ARENA_FLAKY_DIR"]
        counter = os.path.join(folder, self.task + ".count")
        visit = int(open(counter).read()) if os.path.exists(counter) else 0
        with open(counter, "w") as f:
            f.write(str(visit + 1))
        with open(os.path.join(folder, "order.txt"), "a") as f:
            f.write(self.task + "\n")
        pattern = json.loads(os.environ["ARENA_FLAKY_PATTERN"])[self.task]
        self.give_up = pattern[visit % len(pattern)] == "F"

    def predict(self, obs):
        if self.give_up:
            word = "DONE" if self.task == "stub-settings-infeasible" else "FAIL"
            return {"decision": word, "response": f"{self.task}: giving up"}
        return super().predict(obs)
