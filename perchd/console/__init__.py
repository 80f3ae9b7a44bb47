"""What the commands share and nothing else imports: argument checks, the progress display,
the flight config taken from flags, and matplotlib's refusals as one line."""
