"""Evaluation work: the job queue, the scheduler that fills it, and the workers that race
each job in a sandboxed child process."""
