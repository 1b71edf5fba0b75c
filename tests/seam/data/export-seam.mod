MODULE seam
  ! humanpt path export --format rapid: export-seam.json
  ! 4 segments (3 lines, 1 arc), 1 corner, the tip in humanpt's world frame
  ! feed 20 mm/s, blend 1 mm at tangent junctions, 0 mm at corners
  ! robtargets in wobj0 = humanpt's world frame; quaternions [q1,q2,q3,q4] = [w,x,y,z]
  PERS tooldata tSeam := [TRUE,[[0.000,0.000,200.000],[1.0000000,0.0000000,0.0000000,0.0000000]],[1,[0,0,1],[1,0,0,0],0,0,0]];  ! load: 1 kg placeholder
  CONST speeddata vSeam := [20,500,5000,1000];
  CONST zonedata zSeam1 := [FALSE,1.000,1.000,1.000,0.100,1.000,0.100];
  CONST robtarget p0 := [[0.000,0.000,0.000],[0.0000000,0.9659258,0.0000000,-0.2588190],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget p1 := [[100.000,0.000,0.000],[0.0645089,0.9603504,0.0953524,-0.2539166],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget p2 := [[135.355,14.645,0.000],[0.1513856,0.8639846,0.4446027,-0.1814977],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget p3 := [[150.000,50.000,0.000],[0.2164546,0.6431582,0.7298062,-0.0829333],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget p4 := [[150.000,120.000,10.000],[0.1052836,0.6382221,0.7488197,-0.1444194],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget p5 := [[60.000,120.000,10.000],[0.2996478,-0.0468373,0.9524352,0.0297434],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];

  PROC main()
    ConfJ \Off;
    ConfL \Off;
    MoveJ p0, v100, fine, tSeam \WObj:=wobj0;
    MoveL p1, vSeam, zSeam1, tSeam \WObj:=wobj0;
    MoveC p2, p3, vSeam, zSeam1, tSeam \WObj:=wobj0;
    MoveL p4, vSeam, fine, tSeam \WObj:=wobj0;
    MoveL p5, vSeam, fine, tSeam \WObj:=wobj0;
  ENDPROC
ENDMODULE
