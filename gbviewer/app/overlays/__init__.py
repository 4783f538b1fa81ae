"""What is drawn over the panes: labels, legends and the difference views' colour bars."""
