set terminal png size 900,520
set output 'models/medium/eval-val/curve.png'
set title 'Euclidean error over the rollout'
set xlabel 'predicted frame'
set ylabel 'error (mm)'
set key left top
set grid
set datafile missing 'NaN'
plot 'models/medium/eval-val/curve.dat' using 1:2 with linespoints title columnhead(2), 'models/medium/eval-val/curve.dat' using 1:3 with linespoints title columnhead(3), 'models/medium/eval-val/curve.dat' using 1:4 with linespoints title columnhead(4), 'models/medium/eval-val/curve.dat' using 1:5 with linespoints title columnhead(5), 'models/medium/eval-val/curve.dat' using 1:6 with linespoints title columnhead(6), 'models/medium/eval-val/curve.dat' using 1:7 with linespoints title columnhead(7), 'models/medium/eval-val/curve.dat' using 1:8 with linespoints title columnhead(8), 'models/medium/eval-val/curve.dat' using 1:9 with linespoints title columnhead(9)
set output 'models/medium/eval-val/strain.png'
set title 'Edge strain over the rollout (mean over sequences)'
set ylabel 'p99 of |edge length / rest length - 1| (%)'
plot 'models/medium/eval-val/strain.dat' using 1:2 with linespoints title columnhead(2) noenhanced, 'models/medium/eval-val/strain.dat' using 1:3 with linespoints title columnhead(3) noenhanced, 'models/medium/eval-val/strain.dat' using 1:4 with linespoints title columnhead(4) noenhanced, 'models/medium/eval-val/strain.dat' using 1:5 with linespoints title columnhead(5) noenhanced, 'models/medium/eval-val/strain.dat' using 1:6 with linespoints title columnhead(6) noenhanced, 'models/medium/eval-val/strain.dat' using 1:7 with linespoints title columnhead(7) noenhanced, 'models/medium/eval-val/strain.dat' using 1:8 with linespoints title columnhead(8) noenhanced, 'models/medium/eval-val/strain.dat' using 1:9 with linespoints title columnhead(9) noenhanced, 'models/medium/eval-val/strain.dat' using 1:10 with linespoints title columnhead(10) noenhanced
set output 'models/medium/eval-val/speed.png'
set title 'Error against speed (1 thread)'
set xlabel 'ms per frame (median, log scale)'
set ylabel 'error (mm)'
set logscale x
unset key
plot 'models/medium/eval-val/speed.dat' using 1:2 with points pt 7 ps 1.5, '' using 1:2:3 with labels offset 1,1 left
